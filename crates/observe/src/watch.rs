//! What is on the bus, key by key: every sample of the watched keys counted as it arrives
//! (rate, bandwidth, latency from the header stamps, sequence gaps, malformed payloads, age),
//! the nodes alive, the simulator's clock, the fault-injecting nodes' own input reports. One
//! watcher for the three places that show it: `slipstream top`, `up`'s report and the view's
//! page, so they count alike.

use std::collections::BTreeMap;
use std::sync::Arc;
use std::time::Instant;

use parking_lot::Mutex;
use serde::Serialize;

use crate::NodeInput;
use slipstream_contract::bus::{self, Bus, BusError, StatsSnapshot, TopicStats};
use slipstream_contract::msg::{self, MessageKind};
use slipstream_contract::TopicMap;

/// One key as one publisher sends it.
#[derive(Debug, Clone, Serialize)]
pub struct KeyRow {
    pub key: String,
    /// The topic the key is mapped to, when it is one of slipstream's.
    pub topic: Option<&'static str>,
    /// The publishing node (the sample's attachment), when it names itself.
    pub from: Option<String>,
    /// The message type the payloads say they hold.
    pub kind: Option<&'static str>,
    #[serde(flatten)]
    pub stats: StatsSnapshot,
}

/// The simulator's clock as sim/clock last said.
#[derive(Debug, Clone, Serialize)]
pub struct SimView {
    pub sim_time_s: f64,
    pub step: u64,
    pub real_time_factor: f64,
    pub mode: String,
    /// The clock is a recording's, played back (`slipstream play`), not a live simulator's.
    pub replayed: bool,
}

/// One refresh.
#[derive(Debug, Clone, Serialize)]
pub struct TopView {
    pub elapsed_s: f64,
    pub namespace: String,
    pub nodes: Vec<String>,
    pub sim: Option<SimView>,
    pub keys: Vec<KeyRow>,
    /// The inputs of nodes that inject faults (`--faults`), as they report them: injected
    /// drops, delays and duplicates apart from what the network lost.
    pub node_inputs: Vec<NodeInput>,
}

/// Each key seen (with the publisher's encoding, for keys that are not the loop's): its
/// statistics and the message kind it carries.
type KeyStats = BTreeMap<(String, Option<String>), (Arc<TopicStats>, Option<MessageKind>)>;

#[derive(Default)]
struct Seen {
    keys: KeyStats,
    sim: Option<SimView>,
    node_inputs: BTreeMap<String, Vec<StatsSnapshot>>,
}

/// Records every sample of the namespace.
pub struct Watcher {
    seen: Arc<Mutex<Seen>>,
    _subs: Vec<bus::Declared>,
    nodes: bus::NodesWatch,
    topics: TopicMap,
    started: Instant,
}

impl Watcher {
    /// Watches `selectors` (`TopicMap::every_key`, or `TopicMap::every_namespace_key` for
    /// `top --all-namespaces`).
    pub async fn start(bus: &Bus, selectors: &[zenoh::key_expr::OwnedKeyExpr]) -> Result<Watcher, BusError> {
        let seen = Arc::new(Mutex::new(Seen::default()));
        let topics = bus.topics();
        let mut subs = Vec::new();
        for sel in selectors.iter().cloned() {
            let seen = seen.clone();
            let map = topics.clone();
            subs.push(bus.subscribe_samples(sel, false, move |sample| record(&seen, &map, &sample)).await?);
        }
        Ok(Watcher {
            seen,
            _subs: subs,
            nodes: bus.watch_nodes().await?,
            topics: topics.clone(),
            started: Instant::now(),
        })
    }

    /// What was seen so far.
    pub fn view(&self) -> TopView {
        let seen = self.seen.lock();
        let topics = &self.topics;
        let keys = seen
            .keys
            .iter()
            .map(|((key, from), (stats, kind))| KeyRow {
                key: key.clone(),
                topic: zenoh::key_expr::keyexpr::new(key.as_str())
                    .ok()
                    .and_then(|k| topics.topic_of(k))
                    .map(|t| t.name()),
                from: from.clone(),
                kind: kind.map(|k| k.name()),
                // The row names its key and topic: the snapshot's name (the key) would repeat
                // the field `topic` in JSON with another meaning.
                stats: StatsSnapshot { topic: String::new(), ..stats.snapshot() },
            })
            .collect();
        TopView {
            elapsed_s: self.started.elapsed().as_secs_f64(),
            namespace: topics.namespace().to_string(),
            nodes: self.nodes.names(),
            sim: seen.sim.clone(),
            keys,
            node_inputs: seen
                .node_inputs
                .iter()
                .flat_map(|(node, v)| v.iter().map(|stats| NodeInput { node: node.clone(), stats: stats.clone() }))
                .collect(),
        }
    }
}

fn record(seen: &Mutex<Seen>, topics: &TopicMap, sample: &zenoh::sample::Sample) {
    let key = sample.key_expr().as_str().to_string();
    if let Some(node) = topics.node_of_inputs_key(&key) {
        // A node's inputs report (JSON), not a message of the loop.
        #[derive(serde::Deserialize)]
        struct Report {
            inputs: Vec<StatsSnapshot>,
        }
        if let Ok(r) = serde_json::from_slice::<Report>(&sample.payload().to_bytes()) {
            seen.lock().node_inputs.insert(node, r.inputs);
        }
        return;
    }
    if bus::is_foreign(sample, topics) {
        return;
    }
    let from = sample.attachment().and_then(|a| a.try_to_string().ok()).map(|s| s.into_owned());
    let payload = sample.payload().to_bytes();
    // On a topic's key, a message of another type is as wrong as bytes that do not decode.
    let expected = topics.topic_of(sample.key_expr()).map(|t| t.kind());
    let decoded = msg::decode_json(&payload).and_then(|d| match expected {
        Some(kind) if kind != d.0 => Err(msg::DecodeError::WrongKind { expected: kind.name(), found: d.0.name() }),
        _ => Ok(d),
    });
    let replayed = bus::is_replayed(from.as_deref());
    let mut seen = seen.lock();
    let entry =
        seen.keys.entry((key.clone(), from.clone())).or_insert_with(|| (Arc::new(TopicStats::new(key.clone())), None));
    match decoded {
        Ok((kind, header, body)) => {
            entry.0.on_message_from(from.as_deref(), &header, payload.len(), msg::wall_clock_ns());
            entry.1 = Some(kind);
            // A live clock is shown over a replayed one.
            if kind == MessageKind::SimClock && (!replayed || seen.sim.as_ref().is_none_or(|c| c.replayed)) {
                seen.sim = Some(SimView {
                    replayed,
                    sim_time_s: header.stamp_sim_ns as f64 / 1e9,
                    step: body["step"].as_u64().unwrap_or(0),
                    real_time_factor: body["real_time_factor"].as_f64().unwrap_or(0.0),
                    mode: body["mode"].as_str().unwrap_or("?").to_string(),
                });
            }
        }
        Err(e) => {
            entry.1 = msg::peek_kind(&payload).ok();
            entry.0.on_decode_error(&e);
        }
    }
}
