//! When a node of the loop counts as ready, so the simulator may start: its liveliness token
//! is seen (every node of ours, and any node on the contract), or, as a loop file may say
//! instead (`ready.sample`), a first sample arrives on a topic of the loop or a key of the
//! node's own (both under the run's namespace), for a node that declares no token. Either within the node's own timeout. The subscription is made before the node
//! starts, so its first sample cannot pass unseen.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Duration;

use super::foreign::Ready;
use crate::error::{Error, Result};
use slipstream_contract::topics::Topic;
use slipstream_contract::Bus;

/// What one node must show.
pub(crate) struct Watch {
    /// Its process name (logs, errors).
    pub process: String,
    /// Its name on the bus (its token's).
    node: String,
    timeout: Duration,
    /// With `ready.sample`: the key, and whether a sample came.
    sample: Option<(String, Arc<AtomicBool>, zenoh::pubsub::Subscriber<()>)>,
}

impl Watch {
    /// Watches for `node` (started as `process`) to become ready as `ready` says: subscribes
    /// now to its sample's key, a topic of the loop (in its namespace) or a key expression.
    pub(crate) async fn new(bus: &Bus, node: &str, process: &str, ready: &Ready) -> Result<Watch> {
        let sample = match &ready.sample {
            None => None,
            Some(what) => {
                let key = match (Topic::from_name(what), bus.topics().namespace()) {
                    (Some(topic), _) => bus.topics().read_key(topic).to_string(),
                    (None, "") => what.clone(),
                    (None, ns) => format!("{ns}/{what}"),
                };
                let seen = Arc::new(AtomicBool::new(false));
                let flag = seen.clone();
                let sub = bus
                    .session()
                    .declare_subscriber(key.clone())
                    .callback(move |_| flag.store(true, Ordering::Relaxed))
                    .await
                    .map_err(Error::zenoh(format!("{process}: ready.sample `{what}`")))?;
                Some((key, seen, sub))
            }
        };
        let timeout = Duration::from_secs_f64(ready.timeout_s);
        Ok(Watch { process: process.to_string(), node: node.to_string(), timeout, sample })
    }

    /// Whether it is ready, given the names whose tokens are seen.
    pub(crate) fn ready(&self, alive: &[String]) -> bool {
        match &self.sample {
            Some((_, seen, _)) => seen.load(Ordering::Relaxed),
            None => alive.contains(&self.node),
        }
    }

    pub(crate) fn timeout(&self) -> Duration {
        self.timeout
    }

    /// What it was waited for, for a person.
    pub(crate) fn awaited(&self) -> String {
        match &self.sample {
            Some((key, ..)) => format!("no sample on {key} (its ready.sample)"),
            None => {
                // An ego's node is named with its namespace (`car1/acc`): its token is car1/nodes/acc.
                let key = match self.node.rsplit_once('/') {
                    Some((ns, name)) => format!("{ns}/nodes/{name}"),
                    None => format!("nodes/{}", self.node),
                };
                format!("no liveliness token {key} (a node declares it once it listens)")
            }
        }
    }
}
