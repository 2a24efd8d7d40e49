//! The ROS 2 mapping: which of the loop's topics appear to ROS 2, under which name, type and
//! QoS, from the `ros2` block of config/slipstream.json5 laid over the defaults here.
//!
//! A route is one conversion (the front camera's frames to `sensor_msgs/msg/Image`, the ego's
//! state to `nav_msgs/msg/Odometry`, ...). Every route can be renamed, given another QoS or
//! turned off; its type must be one the conversion can produce. The command route (ROS to the
//! loop) is off by default: it lets a ROS 2 controller drive the ego in place of the ACC.

use std::collections::BTreeMap;

use serde::Deserialize;

use super::graph::{Durability, NodeId, Reliability, RosQos};
use super::schema::Distro;
use crate::message_error::Ros2Error;
use slipstream_contract::config::{from_value, CameraEncoding, ConfigError, TopicMap};

/// One conversion between the loop and ROS 2.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Route {
    CameraFront,
    CameraFrontInfo,
    CameraNarrow,
    CameraNarrowInfo,
    Odometry,
    Tf,
    TfStatic,
    Objects,
    Detections,
    Clock,
    AccStatus,
    Command,
}

/// Data flows from the loop to ROS 2, or from ROS 2 into the loop.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Direction {
    ToRos,
    FromRos,
}

const IMAGE: &str = "sensor_msgs/msg/Image";
const COMPRESSED: &str = "sensor_msgs/msg/CompressedImage";

impl Route {
    pub const ALL: [Route; 12] = [
        Route::CameraFront,
        Route::CameraFrontInfo,
        Route::CameraNarrow,
        Route::CameraNarrowInfo,
        Route::Odometry,
        Route::Tf,
        Route::TfStatic,
        Route::Objects,
        Route::Detections,
        Route::Clock,
        Route::AccStatus,
        Route::Command,
    ];

    /// The key of the route in the `ros2.topics` block.
    pub fn id(self) -> &'static str {
        match self {
            Route::CameraFront => "camera_front",
            Route::CameraFrontInfo => "camera_front_info",
            Route::CameraNarrow => "camera_narrow",
            Route::CameraNarrowInfo => "camera_narrow_info",
            Route::Odometry => "odometry",
            Route::Tf => "tf",
            Route::TfStatic => "tf_static",
            Route::Objects => "objects",
            Route::Detections => "detections",
            Route::Clock => "clock",
            Route::AccStatus => "acc_status",
            Route::Command => "command",
        }
    }

    pub fn direction(self) -> Direction {
        if self == Route::Command {
            Direction::FromRos
        } else {
            Direction::ToRos
        }
    }

    /// Name, type, QoS and whether it is on, when the config says nothing. Relative names
    /// resolve under the node's namespace; /tf, /tf_static and /clock are global, as in ROS.
    fn default_entry(self) -> Entry {
        let e =
            |name: &str, ty: &str, qos: RosQos| Entry { name: name.into(), type_name: ty.into(), qos, enabled: true };
        let reliable = |depth| RosQos { depth, ..RosQos::DEFAULT };
        match self {
            Route::CameraFront => e("camera/front/image_raw", IMAGE, RosQos::SENSOR),
            Route::CameraFrontInfo => e("camera/front/camera_info", "sensor_msgs/msg/CameraInfo", RosQos::LATCHED),
            Route::CameraNarrow => e("camera/narrow/image_raw", IMAGE, RosQos::SENSOR),
            Route::CameraNarrowInfo => e("camera/narrow/camera_info", "sensor_msgs/msg/CameraInfo", RosQos::LATCHED),
            Route::Odometry => e("vehicle/odometry", "nav_msgs/msg/Odometry", reliable(10)),
            Route::Tf => e("/tf", "tf2_msgs/msg/TFMessage", reliable(100)),
            Route::TfStatic => e("/tf_static", "tf2_msgs/msg/TFMessage", RosQos::LATCHED),
            Route::Objects => e("objects/markers", "visualization_msgs/msg/MarkerArray", reliable(10)),
            Route::Detections => e("perception/markers", "visualization_msgs/msg/MarkerArray", reliable(10)),
            Route::Clock => e("/clock", "rosgraph_msgs/msg/Clock", reliable(1)),
            Route::AccStatus => e("acc/status", "std_msgs/msg/Float64MultiArray", reliable(10)),
            Route::Command => Entry {
                enabled: false,
                ..e("vehicle/ackermann_cmd", "ackermann_msgs/msg/AckermannDriveStamped", reliable(1))
            },
        }
    }

    /// The types this route can produce (or take).
    pub fn types(self) -> &'static [&'static str] {
        match self {
            Route::CameraFront | Route::CameraNarrow => &[IMAGE, COMPRESSED],
            Route::CameraFrontInfo | Route::CameraNarrowInfo => &["sensor_msgs/msg/CameraInfo"],
            Route::Odometry => &["nav_msgs/msg/Odometry"],
            Route::Tf | Route::TfStatic => &["tf2_msgs/msg/TFMessage"],
            Route::Objects | Route::Detections => &["visualization_msgs/msg/MarkerArray"],
            Route::Clock => &["rosgraph_msgs/msg/Clock"],
            Route::AccStatus => &["std_msgs/msg/Float64MultiArray"],
            Route::Command => &["ackermann_msgs/msg/AckermannDriveStamped"],
        }
    }
}

/// One route as configured.
#[derive(Debug, Clone, PartialEq)]
pub struct Entry {
    /// The ROS topic name, relative (under the node's namespace) or absolute.
    pub name: String,
    pub type_name: String,
    pub qos: RosQos,
    pub enabled: bool,
}

/// The bridge's settings: the node, the distribution's key format, every route.
#[derive(Debug, Clone, PartialEq)]
pub struct Ros2Config {
    pub domain_id: u32,
    pub distro: Distro,
    pub node: String,
    /// The node's ROS namespace (`/` or `/car1`).
    pub namespace: String,
    pub routes: BTreeMap<Route, Entry>,
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct RawRos2 {
    domain_id: Option<u32>,
    distro: Option<Distro>,
    node: Option<String>,
    namespace: Option<String>,
    #[serde(default)]
    topics: BTreeMap<String, RawEntry>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawEntry {
    name: Option<String>,
    #[serde(rename = "type")]
    type_name: Option<String>,
    qos: Option<RawQos>,
    enabled: Option<bool>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawQos {
    reliability: Option<Reliability>,
    durability: Option<Durability>,
    depth: Option<u32>,
}

/// `ROS_DOMAIN_ID` as ROS reads it: a number 0-232, else an error naming the variable.
pub(crate) fn domain_from_env() -> Result<Option<u32>, ConfigError> {
    match std::env::var("ROS_DOMAIN_ID") {
        Err(_) => Ok(None),
        Ok(v) if v.trim().is_empty() => Ok(None),
        Ok(v) => match v.trim().parse::<u32>() {
            Ok(d) if d <= 232 => Ok(Some(d)),
            _ => Err(ConfigError::new(
                "environment",
                "ROS_DOMAIN_ID",
                format!("`{v}` is not a domain id"),
                "set a number from 0 to 232, or unset it for 0",
            )),
        },
    }
}

impl Ros2Config {
    /// The mapping of `topics` (its `ros2` block over the defaults). The domain comes from the
    /// block, else from `ROS_DOMAIN_ID`, else 0; the namespace from the block, else the bus's.
    pub fn from_topic_map(topics: &TopicMap) -> Result<Ros2Config, ConfigError> {
        let origin = topics.origin.as_str();
        let raw: RawRos2 = match &topics.ros2 {
            None => RawRos2::default(),
            Some(v) => from_value(v.clone(), origin, "see the `ros2` block in config/slipstream.json5")
                .map_err(|e| ConfigError { key: format!("ros2.{}", e.key).trim_end_matches('.').into(), ..e })?,
        };
        let namespace = match raw.namespace {
            Some(ns) => ros_namespace(&ns)
                .map_err(|p| ConfigError::new(origin, "ros2.namespace", p.to_string(), "use `/` or `/name`"))?,
            None => format!("/{}", topics.namespace()).trim_end_matches('/').to_string(),
        };
        let node = raw.node.unwrap_or_else(|| "slipstream".into());
        if !valid_name_part(&node) {
            return Err(ConfigError::new(
                origin,
                "ros2.node",
                format!("`{node}` is not a ROS node name"),
                "use letters, digits and _",
            ));
        }
        let domain_id = match raw.domain_id {
            Some(d) => d,
            None => domain_from_env()?.unwrap_or(0),
        };
        let mut routes: BTreeMap<Route, Entry> = Route::ALL.iter().map(|r| (*r, r.default_entry())).collect();
        let compressed_frames = matches!(topics.camera.encoding, CameraEncoding::Jpeg | CameraEncoding::Png);
        if compressed_frames {
            // Frames go out as published: JPEG and PNG as CompressedImage, under image_transport's name.
            for r in [Route::CameraFront, Route::CameraNarrow] {
                let e = routes.get_mut(&r).expect("every route has an entry");
                e.type_name = COMPRESSED.into();
                e.name.push_str("/compressed");
            }
        }
        for (id, over) in raw.topics {
            let route = Route::ALL.into_iter().find(|r| r.id() == id).ok_or_else(|| {
                let ids: Vec<_> = Route::ALL.iter().map(|r| r.id()).collect();
                ConfigError::new(
                    origin,
                    format!("ros2.topics.{id}"),
                    format!("unknown route `{id}`"),
                    format!("use one of: {}", ids.join(", ")),
                )
            })?;
            apply(route, routes.get_mut(&route).expect("every route has an entry"), over, origin)?;
        }
        for r in [Route::CameraFront, Route::CameraNarrow] {
            let compressed = routes[&r].type_name == COMPRESSED;
            if compressed != compressed_frames {
                return Err(ConfigError::new(
                    origin,
                    format!("ros2.topics.{}.type", r.id()),
                    format!(
                        "frames are sent as {:?} (camera.encoding), which {} cannot carry",
                        topics.camera.encoding, routes[&r].type_name
                    ),
                    "leave the type out: it follows camera.encoding (raw, lz4: Image; jpeg, png: CompressedImage)",
                ));
            }
        }
        let namespace = if namespace.is_empty() { "/".to_string() } else { namespace };
        Ok(Ros2Config { domain_id, distro: raw.distro.unwrap_or(Distro::Jazzy), node, namespace, routes })
    }

    /// The node's place in the ROS graph; `zid` is its Zenoh session's id (empty where only
    /// names and keys are wanted).
    pub fn node_id(&self, zid: String) -> NodeId {
        NodeId {
            domain: self.domain_id,
            zid,
            node_id: 0,
            namespace: self.namespace.clone(),
            name: self.node.clone(),
            distro: self.distro,
        }
    }

    /// The routes that are on.
    pub fn enabled(&self) -> impl Iterator<Item = (Route, &Entry)> {
        self.routes.iter().filter(|(_, e)| e.enabled).map(|(r, e)| (*r, e))
    }
}

fn apply(route: Route, entry: &mut Entry, over: RawEntry, origin: &str) -> Result<(), ConfigError> {
    let key = format!("ros2.topics.{}", route.id());
    if let Some(name) = over.name {
        if !valid_topic(&name) {
            return Err(ConfigError::new(
                origin,
                format!("{key}.name"),
                format!("`{name}` is not a ROS topic name"),
                "use letters, digits, _ and / (e.g. `camera/image_raw` or `/clock`)",
            ));
        }
        entry.name = name;
    }
    if let Some(ty) = over.type_name {
        if !route.types().contains(&ty.as_str()) {
            return Err(ConfigError::new(
                origin,
                format!("{key}.type"),
                format!("route `{}` cannot carry `{ty}`", route.id()),
                format!("use {}", route.types().join(" or ")),
            ));
        }
        entry.type_name = ty;
    }
    if let Some(q) = over.qos {
        entry.qos.reliability = q.reliability.unwrap_or(entry.qos.reliability);
        entry.qos.durability = q.durability.unwrap_or(entry.qos.durability);
        if let Some(d) = q.depth {
            if d == 0 || d > 10_000 {
                return Err(ConfigError::new(
                    origin,
                    format!("{key}.qos.depth"),
                    format!("{d} is out of range"),
                    "use 1 to 10000",
                ));
            }
            entry.qos.depth = d;
        }
    }
    entry.enabled = over.enabled.unwrap_or(entry.enabled);
    Ok(())
}

fn valid_name_part(s: &str) -> bool {
    !s.is_empty()
        && s.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
        && !s.starts_with(|c: char| c.is_ascii_digit())
}

/// A ROS topic name: `/`-separated tokens of letters, digits and `_`, not starting with a
/// digit, no empty token.
fn valid_topic(name: &str) -> bool {
    let body = name.strip_prefix('/').unwrap_or(name);
    !body.is_empty() && body.split('/').all(valid_name_part)
}

impl Ros2Config {
    /// The node in ROS namespace `ns` (`/` or `/name`) instead of the config's.
    pub fn set_namespace(&mut self, ns: &str) -> Result<(), Ros2Error> {
        self.namespace = ros_namespace(ns)?;
        Ok(())
    }
}

fn ros_namespace(ns: &str) -> Result<String, Ros2Error> {
    if ns == "/" || ns.is_empty() {
        return Ok("/".into());
    }
    if !ns.starts_with('/') || !valid_topic(ns) {
        return Err(Ros2Error::Namespace(ns.to_string()));
    }
    Ok(ns.trim_end_matches('/').to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn config(text: &str) -> Result<Ros2Config, ConfigError> {
        Ros2Config::from_topic_map(&TopicMap::from_json5(text, "test.json5").unwrap())
    }

    #[test]
    fn defaults_map_every_route_and_leave_commands_off() {
        let c = config("{}").unwrap();
        assert_eq!(c.routes.len(), Route::ALL.len());
        assert!(!c.routes[&Route::Command].enabled);
        assert_eq!(c.routes[&Route::CameraFrontInfo].qos.durability, Durability::TransientLocal);
        assert_eq!(c.namespace, "/");
        assert_eq!(c.distro, Distro::Jazzy);
        let ns = config("{ namespace: 'car1' }").unwrap();
        assert_eq!(ns.namespace, "/car1");
        let jpeg = config("{ camera: { encoding: 'jpeg' } }").unwrap();
        assert_eq!(jpeg.routes[&Route::CameraFront].type_name, COMPRESSED);
        assert_eq!(jpeg.routes[&Route::CameraFront].name, "camera/front/image_raw/compressed");
    }

    #[test]
    fn the_shipped_config_says_what_the_defaults_are() {
        let shipped = TopicMap::from_json5(include_str!("../../../config/slipstream.json5"), "shipped").unwrap();
        let mut from_file = Ros2Config::from_topic_map(&shipped).unwrap();
        let mut defaults = config("{}").unwrap();
        // The domain may come from the environment in both.
        from_file.domain_id = 0;
        defaults.domain_id = 0;
        assert_eq!(from_file, defaults);
    }

    #[test]
    fn overrides_apply_and_bad_keys_say_the_key_and_the_fix() {
        let c = config(
            "{ camera: { encoding: 'jpeg' }, ros2: { distro: 'humble', domain_id: 3, topics: { command: { enabled: true, name: '/cmd' }, \
             camera_front: { type: 'sensor_msgs/msg/CompressedImage', qos: { depth: 1 } } } } }",
        )
        .unwrap();
        assert!(c.routes[&Route::Command].enabled);
        assert_eq!(c.routes[&Route::Command].name, "/cmd");
        assert_eq!(c.routes[&Route::CameraFront].qos.depth, 1);
        assert_eq!((c.domain_id, c.distro), (3, Distro::Humble));

        let e =
            config("{ ros2: { topics: { camera_front: { type: 'sensor_msgs/msg/CompressedImage' } } } }").unwrap_err();
        assert_eq!(e.key, "ros2.topics.camera_front.type", "{e}");
        let e = config("{ ros2: { topics: { clock: { type: 'std_msgs/msg/String' } } } }").unwrap_err();
        assert_eq!(e.key, "ros2.topics.clock.type");
        assert!(e.fix.contains("rosgraph_msgs/msg/Clock"), "{e}");
        let e = config("{ ros2: { topics: { lidar: {} } } }").unwrap_err();
        assert!(e.fix.contains("camera_front"), "{e}");
        let e = config("{ ros2: { topics: { odometry: { name: 'odom//x' } } } }").unwrap_err();
        assert_eq!(e.key, "ros2.topics.odometry.name");
        let e = config("{ ros2: { distro: 'foxy' } }").unwrap_err();
        assert_eq!(e.key, "ros2.distro", "{e}");
        assert_eq!(e.origin, "test.json5");
    }
}
