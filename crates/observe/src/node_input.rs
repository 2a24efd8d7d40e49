//! One input of one node as the node reported it when it ended (or as an observer counted
//! it): what a run's report and `top` list per node and topic. It lives with the bus's
//! observers because every tool that reads a run's figures reads these, from the launcher to
//! the evaluation and the view.

use serde::Serialize;

/// One input of one node as it ended: what arrived, what the network lost (sequence gaps) and
/// what injected faults dropped, delayed or duplicated.
#[derive(Debug, Clone, Serialize, serde::Deserialize)]
pub struct NodeInput {
    pub node: String,
    #[serde(flatten)]
    pub stats: slipstream_contract::bus::StatsSnapshot,
}

impl NodeInput {
    /// "perception/objects at acc: 1,200 arrived, 0 lost on the way, injected 240 dropped, ..."
    pub fn line(&self) -> String {
        let s = &self.stats;
        format!(
            "{} at {}: {} arrived, {} lost on the way; injected: {} dropped, {} delayed, {} duplicated",
            s.topic, self.node, s.received, s.lost, s.injected_dropped, s.injected_delayed, s.injected_duplicated
        )
    }
}
