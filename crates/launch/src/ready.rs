//! When a node of the loop counts as ready, so the simulator may start: its liveliness token
//! is seen (every node of ours, and any node on the contract), or, as a loop file may say
//! instead (`ready.sample`), a first sample arrives on a topic of the loop or a key of the
//! node's own (both under the run's namespace), for a node that declares no token; either
//! within the node's own timeout. The subscription is made before the node starts, so its
//! first sample cannot pass unseen. [`until_ready`] is the one wait on a set of nodes, for
//! `up`'s loop and for the tools that start nodes of their own (`eval platoon`).

use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use super::foreign::Ready;
use super::NODE_POLL;
use crate::error::{Error, Result};
use slipstream_contract::topics::Topic;
use slipstream_contract::Bus;

/// What one node must show.
pub struct Watch {
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
    pub async fn new(bus: &Bus, node: &str, process: &str, ready: &Ready) -> Result<Watch> {
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
    pub fn ready(&self, alive: &[String]) -> bool {
        match &self.sample {
            Some((_, seen, _)) => seen.load(Ordering::Relaxed),
            None => alive.contains(&self.node),
        }
    }

    pub fn timeout(&self) -> Duration {
        self.timeout
    }

    /// What it was waited for, for a person.
    pub fn awaited(&self) -> String {
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

/// Waits until every one of `waits` is ready, given the names `alive` reports seen on the bus;
/// `ended` fails when a node's process has ended meanwhile (one that dies at start is named at
/// once, not after its timeout). Fails naming the first node past its own timeout, with what
/// was seen and where the logs are (`logs`).
pub async fn until_ready(
    waits: &[Watch],
    alive: impl Fn() -> Vec<String>,
    mut ended: impl FnMut() -> Result<()>,
    logs: &Path,
) -> Result<()> {
    let start = Instant::now();
    loop {
        let alive = alive();
        let pending: Vec<&Watch> = waits.iter().filter(|w| !w.ready(&alive)).collect();
        if pending.is_empty() {
            return Ok(());
        }
        ended()?;
        if let Some(w) = pending.iter().find(|w| start.elapsed() >= w.timeout()) {
            let problem = format!(
                "not ready after {:?}: {} (seen on the bus: {alive:?}); see the logs in {}",
                w.timeout(),
                w.awaited(),
                logs.display()
            );
            return Err(Error::node(&w.process, problem));
        }
        tokio::time::sleep(NODE_POLL).await;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn token(node: &str, timeout_ms: u64) -> Watch {
        let process = node.replace('/', "-");
        Watch { process, node: node.to_string(), timeout: Duration::from_millis(timeout_ms), sample: None }
    }

    #[tokio::test]
    async fn every_node_seen_is_ready_and_a_missing_one_is_named_at_its_timeout() {
        let waits = [token("car1/acc", 60_000), token("car2/acc", 60_000)];
        let all = || vec!["car1/acc".to_string(), "car2/acc".to_string(), "sim".to_string()];
        until_ready(&waits, all, || Ok(()), Path::new("/logs")).await.unwrap();

        let waits = [token("car1/acc", 60_000), token("car2/acc", 100)];
        let one = || vec!["car1/acc".to_string()];
        let err = until_ready(&waits, one, || Ok(()), Path::new("/logs")).await.unwrap_err().to_string();
        assert!(err.contains("car2-acc") && err.contains("car2/nodes/acc") && err.contains("/logs"), "{err}");
        assert!(!err.contains("car1-acc"), "{err}");
    }

    #[tokio::test]
    async fn a_node_that_ends_while_awaited_is_named_before_any_timeout() {
        let waits = [token("car1/acc", 60_000)];
        let start = Instant::now();
        let ended = || Err(Error::node("car1-acc", "exited at start (exit status: 2)"));
        let err = until_ready(&waits, Vec::new, ended, Path::new("/logs")).await.unwrap_err().to_string();
        assert!(err.contains("car1-acc") && err.contains("exited at start"), "{err}");
        assert!(start.elapsed() < Duration::from_secs(60), "waited out the timeout");
    }
}
