//! The bus into ROS 2 messages: every route an [`Outlet`] takes, fed from its source topics.
//!
//! Bus samples arrive on Zenoh's receive thread, which only queues a job (a reference to the
//! payload, no copy): frames into an outbox of their own (two deep), everything else into a
//! second one. Each outbox's thread converts to CDR through the [`Translator`] (one copy of a
//! frame's pixels) and hands the result to the outlet; when it falls behind, the oldest job is
//! dropped and counted, so no ROS subscriber and no disk can slow the bus. A route nobody
//! subscribes to is not converted at all (the outlet says, [`Outlet::wanted`]).

use std::collections::{BTreeMap, BTreeSet};
use std::sync::Arc;

use crate::error::{Error, Result};
use serde::Serialize;

use super::mapping::Route;
use super::outbox::{Job, Outbox, RouteCounters};
use super::outlet::Outlet;
use super::translate::Translator;
use slipstream_contract::bus::{Bus, Declared};
use slipstream_contract::topics::Topic;

/// Frames queued for the sending thread at most (each holds the bus's payload, in shared
/// memory on one host): a slow sender skips frames rather than piling them up.
const FRAME_BACKLOG: usize = 2;
/// Other messages queued at most (about a second of the loop's signals).
const SIGNAL_BACKLOG: usize = 512;

/// What one route sent so far.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RouteStats {
    pub route: &'static str,
    pub topic: String,
    pub sent: u64,
    pub bytes: u64,
    /// Dropped before conversion: the sender fell behind (a slow subscriber or disk).
    pub dropped: u64,
    /// Not converted or not sent (a malformed bus payload, a closed link).
    pub failed: u64,
}

/// A running bridge; [`Bridge::stop`] ends it.
pub struct Bridge {
    outlet: Arc<dyn Outlet>,
    counters: Arc<BTreeMap<Route, Arc<RouteCounters>>>,
    outboxes: Vec<(Arc<Outbox>, std::thread::JoinHandle<()>)>,
    subs: Vec<Declared>,
}

impl Bridge {
    /// Subscribes to the sources of `outlet`'s routes on `bus` and starts converting.
    pub async fn start(bus: &Bus, outlet: Arc<dyn Outlet>) -> Result<Bridge> {
        let counters: Arc<BTreeMap<Route, Arc<RouteCounters>>> =
            Arc::new(Route::ALL.iter().map(|r| (*r, Arc::default())).collect());
        let lookup = {
            let c = counters.clone();
            Arc::new(move |r: Route| c[&r].clone())
        };
        let (frames, frames_thread) = Outbox::start("ros2-frames", FRAME_BACKLOG, lookup.clone())
            .map_err(Error::system("start the ROS 2 frames' thread"))?;
        let (signals, signals_thread) = Outbox::start("ros2-signals", SIGNAL_BACKLOG, lookup)
            .map_err(Error::system("start the ROS 2 signals' thread"))?;
        let taken = outlet.routes();
        let types = taken.iter().map(|(r, _, t)| (*r, t.as_str()));
        let translator = Arc::new(Translator::new(bus.topics().namespace()).with_types(types));
        let routes: Vec<Route> = taken.iter().map(|(r, _, _)| *r).collect();
        let topics: BTreeSet<Topic> = routes.iter().flat_map(|r| r.sources().iter().copied()).collect();
        let mut subs = Vec::new();
        for topic in topics {
            let fed: Vec<Route> = routes.iter().copied().filter(|r| r.sources().contains(&topic)).collect();
            let outbox = if matches!(topic, Topic::CameraFront | Topic::CameraNarrow) { &frames } else { &signals };
            let (outbox, outlet, translator) = (outbox.clone(), outlet.clone(), translator.clone());
            let handler = move |sample: zenoh::sample::Sample| {
                for &route in &fed {
                    if !outlet.wanted(route) {
                        continue;
                    }
                    let (payload, outlet, translator) = (sample.payload().clone(), outlet.clone(), translator.clone());
                    let job: Job = Box::new(move || {
                        let bytes = payload.to_bytes();
                        match translator.encode(route, topic, &bytes)? {
                            Some((header, cdr)) => {
                                let n = cdr.len();
                                outlet.put(route, &header, cdr)?;
                                Ok(n)
                            }
                            None => Ok(0),
                        }
                    });
                    outbox.push(route, job);
                }
            };
            let latched = bus.topics().qos(topic).latched;
            subs.push(bus.subscribe_samples(bus.topics().key(topic), latched, handler).await?);
        }
        Ok(Bridge { outlet, counters, outboxes: vec![(frames, frames_thread), (signals, signals_thread)], subs })
    }

    pub fn stats(&self) -> Vec<RouteStats> {
        use std::sync::atomic::Ordering::Relaxed;
        self.outlet
            .routes()
            .into_iter()
            .map(|(route, topic, _)| {
                let c = &self.counters[&route];
                RouteStats {
                    route: route.id(),
                    topic,
                    sent: c.sent.load(Relaxed),
                    bytes: c.bytes.load(Relaxed),
                    dropped: c.dropped.load(Relaxed),
                    failed: c.failed.load(Relaxed),
                }
            })
            .collect()
    }

    /// Stops taking samples and sends what is queued.
    pub async fn stop(mut self) -> Vec<RouteStats> {
        self.subs.clear();
        for (outbox, thread) in self.outboxes.drain(..) {
            outbox.close();
            let _ = tokio::task::spawn_blocking(move || thread.join()).await;
        }
        self.stats()
    }
}

impl Drop for Bridge {
    fn drop(&mut self) {
        for (outbox, _) in &self.outboxes {
            outbox.close();
        }
    }
}
