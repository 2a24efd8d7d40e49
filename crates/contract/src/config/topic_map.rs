//! config/slipstream.json5: namespace, key remapping, per-topic QoS, camera encoding.

use std::collections::BTreeMap;
use std::path::Path;

use serde::Deserialize;
use zenoh::key_expr::OwnedKeyExpr;

use super::{parse_json5, ConfigError};
use crate::msg::ImageEncoding;
use crate::qos::{Congestion, Delivery, Priority, Reliability, SessionKind, TopicQos};
use crate::topics::{Topic, NODES_PREFIX};

/// The last chunk of a node's inputs report key (`nodes/<name>/inputs`).
const INPUTS_SUFFIX: &str = "inputs";

/// Where nodes look for the topic config when no flag names one.
pub const DEFAULT_SLIPSTREAM_CONFIG_PATH: &str = "config/slipstream.json5";

/// How camera frames are put on the wire.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum CameraEncoding {
    /// RGB8 pixels: no encode cost, zero-copy through shared memory on one host.
    Raw,
    /// RGB8 compressed with LZ4: lossless, ~1 ms a frame each way, a few times smaller.
    Lz4,
    /// JPEG at `jpeg_quality`: ~20-50x smaller, lossy, for frames that cross a LAN.
    Jpeg,
    /// PNG: lossless and smaller than LZ4, slower to encode.
    Png,
}

impl CameraEncoding {
    pub const ALL: [CameraEncoding; 4] =
        [CameraEncoding::Raw, CameraEncoding::Lz4, CameraEncoding::Jpeg, CameraEncoding::Png];

    /// The encoding frames carry on the wire.
    pub fn image_encoding(self) -> ImageEncoding {
        match self {
            CameraEncoding::Raw => ImageEncoding::Rgb8,
            CameraEncoding::Lz4 => ImageEncoding::Lz4,
            CameraEncoding::Jpeg => ImageEncoding::Jpeg,
            CameraEncoding::Png => ImageEncoding::Png,
        }
    }

    /// Its name in the config; `@` and the name are the last chunk of a link copy's key
    /// (`camera/front/@lz4`).
    pub fn name(self) -> &'static str {
        match self {
            CameraEncoding::Raw => "raw",
            CameraEncoding::Lz4 => "lz4",
            CameraEncoding::Jpeg => "jpeg",
            CameraEncoding::Png => "png",
        }
    }
}

/// A set of encodings (`camera.link_copies`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct EncodingSet(u8);

impl EncodingSet {
    pub fn of(encodings: &[CameraEncoding]) -> EncodingSet {
        EncodingSet(encodings.iter().fold(0, |bits, e| bits | 1 << *e as u8))
    }

    pub fn contains(self, e: CameraEncoding) -> bool {
        self.0 & (1 << e as u8) != 0
    }

    pub fn iter(self) -> impl Iterator<Item = CameraEncoding> {
        CameraEncoding::ALL.into_iter().filter(move |e| self.contains(*e))
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CameraSettings {
    pub encoding: CameraEncoding,
    pub jpeg_quality: u8,
    /// Size of the shared-memory pool a frame publisher allocates frames from.
    pub shm_pool_mib: usize,
    /// Publish frames through shared memory when a subscriber on this host can read it.
    pub shared_memory: bool,
    /// Copies a frame publisher offers beside its frames, each on `<frames key>/@<encoding>` and
    /// encoded only while a subscriber reads it: a reader across a link picks the one that fits.
    pub link_copies: EncodingSet,
    /// Which copy this node's frame subscribers read; None: the frames as published.
    pub read: Option<CameraEncoding>,
    /// A frame reader on a thread of its own (the detector) is awake and polling in a short
    /// window around each frame of a periodic camera instead of being woken for it
    /// (crates/contract/src/bus/cadence.rs): ~60 us less per frame for ~2 % of a core per camera at 20 Hz.
    pub poll_before_frame: bool,
}

impl Default for CameraSettings {
    fn default() -> Self {
        CameraSettings {
            encoding: CameraEncoding::Raw,
            jpeg_quality: 85,
            shm_pool_mib: 64,
            shared_memory: true,
            link_copies: EncodingSet::of(&[CameraEncoding::Lz4, CameraEncoding::Jpeg]),
            read: None,
            poll_before_frame: true,
        }
    }
}

/// One topic after namespace, remapping and QoS overrides.
#[derive(Debug, Clone, PartialEq)]
pub struct ResolvedTopic {
    /// The key as configured (without the namespace).
    pub key: OwnedKeyExpr,
    /// Given with a leading `/`: the namespace does not apply.
    pub absolute: bool,
    pub qos: TopicQos,
}

/// Logical topic -> key and QoS, for every topic; what every node consults.
#[derive(Debug, Clone, PartialEq)]
pub struct TopicMap {
    namespace: String,
    entries: BTreeMap<Topic, ResolvedTopic>,
    pub camera: CameraSettings,
    /// The file it was read from, for messages.
    pub origin: String,
    /// The `ros2` block as written (the ROS 2 bridge reads and checks it: crates/ros2/src/mapping.rs);
    /// None when the file has none.
    pub ros2: Option<serde_json::Value>,
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct RawFile {
    #[serde(default)]
    namespace: String,
    #[serde(default)]
    camera: RawCamera,
    #[serde(default)]
    topics: BTreeMap<String, RawTopic>,
    #[serde(default)]
    ros2: Option<serde_json::Value>,
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct RawCamera {
    encoding: Option<CameraEncoding>,
    link_copies: Option<Vec<CameraEncoding>>,
    read: Option<String>,
    jpeg_quality: Option<u8>,
    shm_pool_mib: Option<usize>,
    shared_memory: Option<bool>,
    poll_before_frame: Option<bool>,
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct RawTopic {
    key: Option<String>,
    priority: Option<Priority>,
    express: Option<bool>,
    congestion_control: Option<Congestion>,
    reliability: Option<Reliability>,
    max_rate_hz: Option<f64>,
    delivery: Option<Delivery>,
    session: Option<SessionKind>,
    latched: Option<bool>,
}

impl Default for TopicMap {
    fn default() -> Self {
        let mut map = TopicMap {
            namespace: String::new(),
            entries: BTreeMap::new(),
            camera: CameraSettings::default(),
            origin: "built-in defaults".to_string(),
            ros2: None,
        };
        for t in Topic::ALL {
            let key = key_expr(t.name()).expect("default topic names are valid keys");
            map.entries.insert(t, ResolvedTopic { key, absolute: false, qos: t.default_qos() });
        }
        map
    }
}

impl TopicMap {
    /// Reads a topic config file.
    pub fn load(path: &Path) -> Result<TopicMap, ConfigError> {
        let origin = ConfigError::file(path);
        let text = std::fs::read_to_string(path).map_err(|e| {
            ConfigError::new(
                &origin,
                "",
                format!("cannot read the file: {e}"),
                "check the path given to --topics / SLIPSTREAM_CONFIG",
            )
        })?;
        TopicMap::from_json5(&text, &origin)
    }

    /// Loads `path` if given, else config/slipstream.json5 if it exists, else the defaults.
    pub fn load_or_default(path: Option<&Path>) -> Result<TopicMap, ConfigError> {
        match path {
            Some(p) => TopicMap::load(p),
            None if Path::new(DEFAULT_SLIPSTREAM_CONFIG_PATH).is_file() => {
                TopicMap::load(Path::new(DEFAULT_SLIPSTREAM_CONFIG_PATH))
            }
            None => Ok(TopicMap::default()),
        }
    }

    /// Parses config text; `origin` names it in errors.
    pub fn from_json5(text: &str, origin: &str) -> Result<TopicMap, ConfigError> {
        let raw: RawFile = parse_json5(
            text,
            origin,
            "see the comments in config/slipstream.json5 for every key and its allowed values",
        )?;
        TopicMap::from_raw(raw, origin)
    }

    fn from_raw(raw: RawFile, origin: &str) -> Result<TopicMap, ConfigError> {
        let mut map = TopicMap { origin: origin.to_string(), ros2: raw.ros2, ..TopicMap::default() };
        map.set_namespace(&raw.namespace).map_err(|e| e.at(origin, "namespace"))?;

        let cam = raw.camera;
        if let Some(q) = cam.jpeg_quality {
            if !(1..=100).contains(&q) {
                return Err(ConfigError::new(
                    origin,
                    "camera.jpeg_quality",
                    format!("{q} is out of range"),
                    "use a quality from 1 to 100",
                ));
            }
            map.camera.jpeg_quality = q;
        }
        if let Some(mib) = cam.shm_pool_mib {
            if !(4..=4096).contains(&mib) {
                return Err(ConfigError::new(
                    origin,
                    "camera.shm_pool_mib",
                    format!("{mib} MiB is out of range"),
                    "use 4 to 4096 MiB; 64 holds ~70 frames of 640x480",
                ));
            }
            map.camera.shm_pool_mib = mib;
        }
        map.camera.encoding = cam.encoding.unwrap_or(map.camera.encoding);
        if let Some(copies) = cam.link_copies {
            map.camera.link_copies = EncodingSet::of(&copies);
        }
        map.camera.read = match cam.read.as_deref() {
            None | Some("published") => None,
            Some(name) => Some(CameraEncoding::ALL.into_iter().find(|e| e.name() == name).ok_or_else(|| {
                ConfigError::new(
                    origin,
                    "camera.read",
                    format!("`{name}` is not a frame encoding"),
                    "use \"published\" (the frames as the simulator sends them) or a link copy: \"raw\", \"lz4\", \"jpeg\", \"png\"",
                )
            })?),
        };
        map.camera.shared_memory = cam.shared_memory.unwrap_or(map.camera.shared_memory);
        map.camera.poll_before_frame = cam.poll_before_frame.unwrap_or(map.camera.poll_before_frame);

        for (name, over) in raw.topics {
            map.apply_override(&name, over, origin)?;
        }
        Ok(map)
    }

    /// One topic's entry of `topics` in the file: key remapping and QoS over the defaults.
    fn apply_override(&mut self, name: &str, over: RawTopic, origin: &str) -> Result<(), ConfigError> {
        let key_path = format!("topics.{name}");
        let Some(topic) = Topic::from_name(name) else {
            let allowed: Vec<_> = Topic::ALL.iter().map(|t| t.name()).collect();
            return Err(ConfigError::new(
                origin,
                key_path,
                format!("unknown topic `{name}`"),
                format!("use one of: {}", allowed.join(", ")),
            ));
        };
        let entry = self.entries.get_mut(&topic).expect("every topic has an entry");
        if let Some(k) = over.key {
            let (key, absolute) = remapped_key(&k).map_err(|e| e.at(origin, format!("{key_path}.key")))?;
            entry.key = key;
            entry.absolute = absolute;
        }
        let q = &mut entry.qos;
        q.priority = over.priority.unwrap_or(q.priority);
        q.express = over.express.unwrap_or(q.express);
        q.congestion_control = over.congestion_control.unwrap_or(q.congestion_control);
        q.reliability = over.reliability.unwrap_or(q.reliability);
        q.latched = over.latched.unwrap_or(q.latched);
        q.session = over.session.unwrap_or(q.session);
        if q.session == SessionKind::LowLatency && topic.kind() == crate::msg::MessageKind::CameraFrame {
            return Err(ConfigError::new(
                origin,
                format!("{key_path}.session"),
                "frames cannot ride the low-latency session: its transport does not fragment, and a frame is larger than one 64 KiB batch",
                "leave camera topics on \"main\" (the session with priorities)",
            ));
        }
        if let Some(d) = over.delivery {
            if d == Delivery::Queue(0) {
                return Err(ConfigError::new(
                    origin,
                    format!("{key_path}.delivery"),
                    "a queue of 0",
                    "use \"latest\" or { queue: N } with N >= 1",
                ));
            }
            q.delivery = d;
        }
        if let Some(r) = over.max_rate_hz {
            if !(r.is_finite() && r > 0.0) {
                return Err(ConfigError::new(
                    origin,
                    format!("{key_path}.max_rate_hz"),
                    format!("{r} is not a positive rate"),
                    "give a rate in Hz > 0, or leave the key out for no limit",
                ));
            }
            q.max_rate_hz = Some(r);
        }
        Ok(())
    }

    /// This map with every topic blocking rather than dropping under congestion: what a node
    /// publishes with in lockstep ([`crate::Bus::keep_every_message`]).
    pub fn lossless(&self) -> TopicMap {
        let mut map = self.clone();
        for entry in map.entries.values_mut() {
            entry.qos.congestion_control = Congestion::Block;
        }
        map
    }

    /// Replaces the namespace (the `--namespace` flag does this after loading).
    pub fn with_namespace(mut self, namespace: &str) -> Result<TopicMap, ConfigError> {
        self.set_namespace(namespace).map_err(|e| e.at("--namespace", "namespace"))?;
        Ok(self)
    }

    fn set_namespace(&mut self, namespace: &str) -> Result<(), BadKey> {
        let ns = namespace.trim_matches('/');
        if !ns.is_empty() {
            let ke = key_expr(ns)?;
            if ke.as_str().contains('*') || ke.as_str().contains('$') {
                return Err(BadKey::new(
                    format!("`{ns}` has a wildcard"),
                    "a namespace is a plain key such as `car1` or `lab/rig2`",
                ));
            }
        }
        self.namespace = ns.to_string();
        Ok(())
    }

    pub fn namespace(&self) -> &str {
        &self.namespace
    }

    /// The topic's resolved entry.
    pub fn get(&self, topic: Topic) -> &ResolvedTopic {
        &self.entries[&topic]
    }

    /// The key a topic is published on: `<namespace>/<key>`, or the remapped key as is when it
    /// was given absolute (leading `/`).
    pub fn key(&self, topic: Topic) -> OwnedKeyExpr {
        let entry = self.get(topic);
        if entry.absolute {
            entry.key.clone()
        } else {
            self.full_key(&entry.key)
        }
    }

    /// The key of a frame topic's link copy in `encoding`: `<key>/@<encoding>` (camera/front/@lz4).
    pub fn copy_key(&self, topic: Topic, encoding: CameraEncoding) -> OwnedKeyExpr {
        // A verbatim chunk (`@`): wildcards never match it, so a `**` subscriber (record, top,
        // echo) neither receives copies nor makes them wanted.
        self.key(topic).join(&format!("@{}", encoding.name())).expect("@ and an encoding name make a verbatim chunk")
    }

    /// The key this node's subscribers read `topic` from: for a camera frame topic, the link
    /// copy `camera.read` names (if any); else the topic's key.
    pub fn read_key(&self, topic: Topic) -> OwnedKeyExpr {
        match (topic.kind(), self.camera.read) {
            (crate::msg::MessageKind::CameraFrame, Some(copy)) => self.copy_key(topic, copy),
            _ => self.key(topic),
        }
    }

    pub fn qos(&self, topic: Topic) -> TopicQos {
        self.get(topic).qos
    }

    /// Liveliness key of a node: `<namespace>/nodes/<name>`.
    pub fn node_key(&self, node: &str) -> Result<OwnedKeyExpr, ConfigError> {
        let rel = key_expr(&format!("{NODES_PREFIX}/{node}")).map_err(|e| e.at("node name", ""))?;
        Ok(self.full_key(&rel))
    }

    /// Where a node that injects faults reports its inputs' statistics (JSON, once a second).
    pub fn node_inputs_key(&self, node: &str) -> Result<OwnedKeyExpr, ConfigError> {
        let rel = key_expr(&format!("{NODES_PREFIX}/{node}/{INPUTS_SUFFIX}")).map_err(|e| e.at("node name", ""))?;
        Ok(self.full_key(&rel))
    }

    /// The node whose inputs report `key` is, if it is one.
    pub fn node_of_inputs_key(&self, key: &str) -> Option<String> {
        let prefix = self.nodes_selector().as_str().trim_end_matches("**").to_string();
        let rest = key.strip_prefix(&prefix)?.strip_suffix(&format!("/{INPUTS_SUFFIX}"))?;
        (!rest.is_empty() && !rest.contains('/')).then(|| rest.to_string())
    }

    /// All node tokens under this namespace.
    pub fn nodes_selector(&self) -> OwnedKeyExpr {
        self.full_key(&key_expr(&format!("{NODES_PREFIX}/**")).expect("valid"))
    }

    /// Key expressions that cover every key of this map, for tools that watch all topics
    /// (`top`, `record`, the view): the namespace, and any topic remapped to an absolute key
    /// outside it. The default namespace is the root of every other: there the map's own
    /// keys are each topic's key and the nodes' keys, so that a tool at the root sees the root
    /// loop and not `loop-2/...` or `car1/...` ([`Self::every_namespace_key`] is for that).
    /// A node that reads a frame link copy (`camera.read`) gets every topic at the key it reads
    /// it from, and the nodes' keys, instead of the whole namespace: a `**` would pull the raw
    /// frames across the link that the copy is there to spare.
    pub fn every_key(&self) -> Vec<OwnedKeyExpr> {
        if self.camera.read.is_some() {
            return self.nodes_and_each_topic(|t| self.read_key(t));
        }
        if self.namespace.is_empty() {
            return self.nodes_and_each_topic(|t| self.key(t));
        }
        let all = self.all_selector();
        let mut selectors = vec![all.clone()];
        for t in crate::topics::Topic::ALL {
            let key = self.key(t);
            if !all.includes(&key) && !selectors.contains(&key) {
                selectors.push(key);
            }
        }
        selectors
    }

    /// Every key of every namespace (`top --all-namespaces`, `record --all-namespaces`): the
    /// whole bus, other loops and anyone's keys included.
    pub fn every_namespace_key(&self) -> Vec<OwnedKeyExpr> {
        vec![key_expr("**").expect("valid")]
    }

    /// The nodes' keys and each topic's key as `key_of` gives it, once each.
    fn nodes_and_each_topic(&self, key_of: impl Fn(crate::topics::Topic) -> OwnedKeyExpr) -> Vec<OwnedKeyExpr> {
        let mut selectors = vec![self.nodes_selector()];
        for t in crate::topics::Topic::ALL {
            let key = key_of(t);
            if !selectors.contains(&key) {
                selectors.push(key);
            }
        }
        selectors
    }

    pub fn all_selector(&self) -> OwnedKeyExpr {
        if self.namespace.is_empty() {
            key_expr("**").expect("valid")
        } else {
            key_expr(&format!("{}/**", self.namespace)).expect("valid")
        }
    }

    /// Which topic a received key belongs to, if any.
    pub fn topic_of(&self, key: &zenoh::key_expr::keyexpr) -> Option<Topic> {
        Topic::ALL.into_iter().find(|t| self.key(*t).as_str() == key.as_str())
    }

    fn full_key(&self, rel: &OwnedKeyExpr) -> OwnedKeyExpr {
        if self.namespace.is_empty() {
            rel.clone()
        } else {
            key_expr(&format!("{}/{}", self.namespace, rel)).expect("namespace and key are valid")
        }
    }
}

/// A key that is no valid key, before it is known which file and key it came from: what is
/// wrong and how to fix it ([`BadKey::at`] names them).
#[derive(Debug)]
struct BadKey {
    problem: String,
    fix: String,
}

impl BadKey {
    fn new(problem: impl Into<String>, fix: impl Into<String>) -> BadKey {
        BadKey { problem: problem.into(), fix: fix.into() }
    }

    fn at(self, origin: impl Into<String>, key: impl Into<String>) -> ConfigError {
        ConfigError::new(origin, key, self.problem, self.fix)
    }
}

fn key_expr(s: &str) -> Result<OwnedKeyExpr, BadKey> {
    OwnedKeyExpr::autocanonize(s.to_string()).map_err(|e| {
        BadKey::new(
            format!("`{s}` is not a valid Zenoh key: {e}"),
            "use chunks of letters, digits, `-` and `_` separated by `/`",
        )
    })
}

/// A remapped key: relative (`car/speed`, namespace applies) or absolute (`/fleet/speed`).
fn remapped_key(s: &str) -> Result<(OwnedKeyExpr, bool), BadKey> {
    let (absolute, body) = match s.strip_prefix('/') {
        Some(rest) => (true, rest),
        None => (false, s),
    };
    if body.is_empty() {
        return Err(BadKey::new("an empty key", "give a key such as `vehicle/speed`, or leave the key out"));
    }
    let ke = key_expr(body)?;
    if ke.as_str().contains('*')
        || ke.as_str().contains('$')
        || ke.as_str().starts_with('@')
        || ke.as_str().contains("/@")
    {
        return Err(BadKey::new(
            format!("`{s}` has a wildcard or a verbatim (@) chunk"),
            "publish keys are plain: chunks of letters, digits, `-` and `_`",
        ));
    }
    Ok((ke, absolute))
}
