//! What `conform sim` saw on the bus: every sample's header and arrival time per key, the
//! fields the rules read, and what conform itself sent. Plain data, filled by the watcher
//! (watch.rs) and judged by the rules (rules.rs), so the rules are tested without a bus.

use std::collections::BTreeMap;

use crate::msg::{CameraInfo, ControlCommand, Header, ImageEncoding, SimClock};

/// One sample as it arrived.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Seen {
    pub header: Header,
    /// Wall-clock seconds since conform started watching.
    pub arrived_s: f64,
}

/// Everything that arrived on one key.
#[derive(Debug, Clone, Default)]
pub struct KeyLog {
    /// The key after namespace and remapping.
    pub key: String,
    /// Samples that decoded strictly, in arrival order.
    pub seen: Vec<Seen>,
    /// Payloads that did not decode as the key's type.
    pub bad: u64,
    /// The first decoding error, as the decoder worded it.
    pub first_bad: Option<String>,
}

impl KeyLog {
    pub fn new(key: impl Into<String>) -> KeyLog {
        KeyLog { key: key.into(), ..KeyLog::default() }
    }

    pub fn push(&mut self, header: Header, arrived_s: f64) {
        self.seen.push(Seen { header, arrived_s });
    }

    pub fn reject(&mut self, error: String) {
        self.bad += 1;
        self.first_bad.get_or_insert(error);
    }

    /// Median simulated interval between consecutive sequence numbers, in seconds: the rate
    /// the publisher runs at, whatever was lost on the way.
    pub fn median_interval_s(&self) -> Option<f64> {
        let mut per_seq: Vec<f64> = self
            .seen
            .windows(2)
            .filter(|w| w[1].header.seq > w[0].header.seq && w[1].header.stamp_sim_ns >= w[0].header.stamp_sim_ns)
            .map(|w| {
                let dt = (w[1].header.stamp_sim_ns - w[0].header.stamp_sim_ns) as f64 / 1e9;
                dt / (w[1].header.seq - w[0].header.seq) as f64
            })
            .collect();
        if per_seq.is_empty() {
            return None;
        }
        per_seq.sort_by(f64::total_cmp);
        Some(per_seq[per_seq.len() / 2])
    }

    /// Messages missing between the first and the last sequence number seen.
    pub fn gaps(&self) -> u64 {
        self.seen.windows(2).map(|w| w[1].header.seq.saturating_sub(w[0].header.seq).saturating_sub(1)).sum()
    }
}

/// A vehicle/state sample's fields that the rules read.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StateSeen {
    pub stamp_sim_ns: u64,
    pub step: u64,
    pub applied: ControlCommand,
    /// control_timing.command_stamp_pub_ns, when the simulator reports it.
    pub command_stamp_pub_ns: Option<u64>,
    pub arrived_s: f64,
}

/// One ground-truth object in one objects message: where it is and how fast it moves,
/// relative to the ego.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ObjectSeen {
    pub stamp_sim_ns: u64,
    pub id: u32,
    pub position_in_ego_m: [f64; 2],
    pub velocity_in_ego_mps: [f64; 2],
}

/// A frame's size and encoding.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameSeen {
    pub width: u32,
    pub height: u32,
    pub encoding: ImageEncoding,
}

/// The control probe: conform's own commands in realtime and fast mode.
#[derive(Debug, Clone, Default)]
pub struct ProbeLog {
    /// When the first command went out (seconds since watching began).
    pub started_s: f64,
    /// The command sent, every time.
    pub command: Option<ControlCommand>,
    pub sent: u64,
}

/// Lockstep: conform as the controller the simulator waits for.
#[derive(Debug, Clone, Default)]
pub struct LockstepLog {
    /// The node name conform answered as.
    pub name: String,
    /// Every step answered, with the command sent.
    pub answered: BTreeMap<u64, ControlCommand>,
}

/// All of it, for one run of `conform sim`.
#[derive(Debug, Clone, Default)]
pub struct Observed {
    /// Wall-clock seconds watched.
    pub window_s: f64,
    pub speed: KeyLog,
    pub state: KeyLog,
    pub clock: KeyLog,
    pub camera: KeyLog,
    pub camera_info: KeyLog,
    pub objects: KeyLog,
    pub road: KeyLog,
    pub ego: KeyLog,
    pub narrow: KeyLog,
    pub events: KeyLog,
    pub states: Vec<StateSeen>,
    pub clocks: Vec<SimClock>,
    pub frames: Vec<FrameSeen>,
    pub objects_seen: Vec<ObjectSeen>,
    pub info: Option<CameraInfo>,
    /// A subscriber declared after the start: seconds until it got the camera info (None:
    /// never; not asked when the watch ended first).
    pub late_info_after_s: Option<f64>,
    pub late_info_asked: bool,
    /// ScenarioEnd's reason, when the scenario ended during the watch.
    pub ended: Option<String>,
    /// Nodes named by ControlTimeout events.
    pub timeouts: Vec<Vec<String>>,
    pub probe: Option<ProbeLog>,
    pub lockstep: Option<LockstepLog>,
}
