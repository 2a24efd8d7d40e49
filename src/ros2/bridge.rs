//! The ROS 2 face of the bus: a ROS node (`slipstream` by default) that republishes the
//! loop's topics as ROS 2 messages on rmw_zenoh's keys and, when the command route is on,
//! takes a ROS controller's commands into vehicle/control.
//!
//! Bus samples arrive on Zenoh's receive thread, which only queues a job: frames into an
//! outbox of their own (two deep), everything else into a second one. Each outbox's thread
//! converts to CDR (one copy of a frame's pixels) and puts; when it falls behind, the oldest
//! job is dropped and counted, so no ROS subscriber can slow the bus.

use std::collections::BTreeMap;
use std::sync::Arc;

use anyhow::Result;
use parking_lot::Mutex;
use serde::Serialize;

use super::convert::{self, Frames, RosImage};
use super::mapping::{Direction, Entry, Ros2Config, Route};
use super::messages::{to_cdr, TfMessage, TransformStamped};
use super::node::{RosNode, RosPublisher};
use super::outbox::{Job, Outbox, RouteCounters};
use crate::bus::{Bus, CallbackSubscriber, Received};
use crate::msg::{AccStatus, CameraInfo, Detections, GroundTruthObjects, SimClock, VehicleState};
use crate::topics::{self, TopicDef};
use crate::vehicle::VehicleParams;

use super::inbound::CommandPath;

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
    #[serde(rename = "type")]
    pub type_name: String,
    pub sent: u64,
    pub bytes: u64,
    pub dropped: u64,
    pub failed: u64,
}

/// The bridge's counters.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct BridgeStats {
    pub routes: Vec<RouteStats>,
    pub commands: Option<super::command::CommandStats>,
}

/// A running bridge; [`Bridge::stop`] ends it.
pub struct Bridge {
    node: Arc<RosNode>,
    counters: Arc<BTreeMap<Route, Arc<RouteCounters>>>,
    publishers: BTreeMap<Route, Arc<RosPublisher>>,
    outboxes: Vec<(Arc<Outbox>, std::thread::JoinHandle<()>)>,
    subs: Vec<CallbackSubscriber>,
    commands: Option<CommandPath>,
}

/// What a job needs to send one route's message.
#[derive(Clone)]
struct Sender {
    publisher: Arc<RosPublisher>,
    outbox: Arc<Outbox>,
    route: Route,
}

impl Sender {
    fn push(&self, job: impl FnOnce(&RosPublisher) -> Result<usize> + Send + 'static) {
        let p = self.publisher.clone();
        let job: Job = Box::new(move || job(&p));
        self.outbox.push(self.route, job);
    }
}

/// Serializes and puts `msg`; the bytes sent.
fn put<T: Serialize>(p: &RosPublisher, msg: &T, size_hint: usize) -> Result<usize> {
    let cdr = to_cdr(msg, size_hint).map_err(anyhow::Error::msg)?;
    let n = cdr.len();
    p.put(cdr)?;
    Ok(n)
}

impl Bridge {
    /// Declares the ROS node and its endpoints on `bus`'s session and starts republishing.
    /// `vehicle` is the ego's model, for turning ROS commands into throttle and brake.
    pub async fn start(bus: &Bus, config: &Ros2Config, vehicle: VehicleParams) -> Result<Bridge> {
        let node = Arc::new(RosNode::declare(bus.session(), config).await?);
        let counters: Arc<BTreeMap<Route, Arc<RouteCounters>>> =
            Arc::new(Route::ALL.iter().map(|r| (*r, Arc::default())).collect());
        let lookup = {
            let c = counters.clone();
            Arc::new(move |r: Route| c[&r].clone())
        };
        let (frames, frames_thread) = Outbox::start("ros2-frames", FRAME_BACKLOG, lookup.clone())?;
        let (signals, signals_thread) = Outbox::start("ros2-signals", SIGNAL_BACKLOG, lookup)?;
        let mut publishers = BTreeMap::new();
        for (route, entry) in config.enabled().filter(|(r, _)| r.direction() == Direction::ToRos) {
            publishers.insert(route, Arc::new(node.publisher(&entry.name, &entry.type_name, entry.qos).await?));
        }
        let sender = |route: Route| {
            let outbox = if matches!(route, Route::CameraFront | Route::CameraNarrow) { &frames } else { &signals };
            publishers.get(&route).map(|p| Sender { publisher: p.clone(), outbox: outbox.clone(), route })
        };
        let frames_of = Frames::new(bus.topics().namespace());
        let mut subs = Vec::new();
        subs.extend(subscribe_cameras(bus, &sender, &frames_of).await?);
        subs.extend(subscribe_signals(bus, &sender, &frames_of).await?);
        let commands = match config.routes.get(&Route::Command).filter(|e| e.enabled) {
            Some(entry) => Some(CommandPath::start(bus, &node, entry, vehicle).await?),
            None => None,
        };
        for (route, p) in &publishers {
            tracing::info!(route = route.id(), topic = %p.topic, key = %p.key, "ROS 2 publisher");
        }
        Ok(Bridge {
            node,
            counters,
            publishers,
            outboxes: vec![(frames, frames_thread), (signals, signals_thread)],
            subs,
            commands,
        })
    }

    /// The ROS node's graph identity (namespace, name, domain).
    pub fn node(&self) -> &super::graph::NodeId {
        &self.node.id
    }

    pub fn stats(&self) -> BridgeStats {
        use std::sync::atomic::Ordering::Relaxed;
        let routes = self
            .publishers
            .iter()
            .map(|(route, p)| {
                let c = &self.counters[route];
                RouteStats {
                    route: route.id(),
                    topic: p.topic.clone(),
                    type_name: p.type_name.clone(),
                    sent: c.sent.load(Relaxed),
                    bytes: c.bytes.load(Relaxed),
                    dropped: c.dropped.load(Relaxed),
                    failed: c.failed.load(Relaxed),
                }
            })
            .collect();
        BridgeStats { routes, commands: self.commands.as_ref().map(CommandPath::stats) }
    }

    /// Stops taking samples, sends what is queued, and undeclares the node.
    pub async fn stop(mut self) -> BridgeStats {
        self.subs.clear();
        let commands = self.commands.take().map(|c| c.stats());
        for (outbox, thread) in self.outboxes.drain(..) {
            outbox.close();
            let _ = tokio::task::spawn_blocking(move || thread.join()).await;
        }
        BridgeStats { commands, ..self.stats() }
    }
}

impl Drop for Bridge {
    fn drop(&mut self) {
        for (outbox, _) in &self.outboxes {
            outbox.close();
        }
    }
}

/// Both cameras' frames and calibration, and the mounts on /tf_static.
async fn subscribe_cameras(
    bus: &Bus,
    sender: &impl Fn(Route) -> Option<Sender>,
    frames: &Frames,
) -> Result<Vec<CallbackSubscriber>> {
    let mounts: Arc<Mutex<BTreeMap<&'static str, Vec<TransformStamped>>>> = Arc::default();
    let mut subs = Vec::new();
    for (name, frame_topic, info_topic, frame_route, info_route) in [
        ("front", topics::CAMERA_FRONT, topics::CAMERA_FRONT_INFO, Route::CameraFront, Route::CameraFrontInfo),
        ("narrow", topics::CAMERA_NARROW, topics::CAMERA_NARROW_INFO, Route::CameraNarrow, Route::CameraNarrowInfo),
    ] {
        let optical = frames.camera(name).1;
        if let Some(s) = sender(frame_route) {
            let optical = optical.clone();
            subs.push(
                bus.subscribe_frames_with(frame_topic, move |f| {
                    let optical = optical.clone();
                    s.push(move |p| {
                        let stamped = f.frame();
                        let size = stamped.msg.data.len() + 128;
                        match convert::image(stamped.header.stamp_sim_ns, optical, &stamped.msg) {
                            RosImage::Raw(img) => put(p, &img, size),
                            RosImage::Compressed(img) => put(p, &img, size),
                        }
                    })
                })
                .await?,
            );
        }
        let info_sender = sender(info_route);
        let static_sender = sender(Route::TfStatic);
        if info_sender.is_none() && static_sender.is_none() {
            continue;
        }
        let (frames, mounts) = (frames.clone(), mounts.clone());
        subs.push(
            bus.subscribe_with(info_topic, move |i: Received<CameraInfo>| {
                if let Some(s) = &info_sender {
                    let (optical, info) = (optical.clone(), i.msg.clone());
                    let stamp = i.header.stamp_sim_ns;
                    s.push(move |p| put(p, &convert::camera_info(stamp, optical, &info), 512));
                }
                if let Some(s) = &static_sender {
                    let all = {
                        let mut m = mounts.lock();
                        m.insert(name, convert::mount_transforms(&frames, name, &i.msg));
                        TfMessage { transforms: m.values().flatten().cloned().collect() }
                    };
                    s.push(move |p| put(p, &all, 512));
                }
            })
            .await?,
        );
    }
    Ok(subs)
}

/// Subscribes `def` when `route` is on, queueing `convert`'s message for every sample.
async fn route<M, R, F>(bus: &Bus, s: Option<Sender>, def: TopicDef<M>, convert: F) -> Result<Option<CallbackSubscriber>>
where
    M: crate::msg::Message + serde::de::DeserializeOwned + Clone + Send + 'static,
    R: Serialize + Send + 'static,
    F: Fn(&Received<M>) -> R + Send + Sync + 'static,
{
    let Some(s) = s else { return Ok(None) };
    let sub = bus
        .subscribe_with(def, move |m: Received<M>| {
            let msg = convert(&m);
            s.push(move |p| put(p, &msg, 256));
        })
        .await?;
    Ok(Some(sub))
}

/// The ego's odometry and /tf, boxes, the clock and the ACC's status.
async fn subscribe_signals(
    bus: &Bus,
    sender: &impl Fn(Route) -> Option<Sender>,
    frames: &Frames,
) -> Result<Vec<CallbackSubscriber>> {
    let (f1, f2, f3, f4) = (frames.clone(), frames.clone(), frames.clone(), frames.clone());
    let subs = [
        route(bus, sender(Route::Odometry), topics::VEHICLE_STATE, move |s: &Received<VehicleState>| {
            convert::odometry(s.header.stamp_sim_ns, &f1, &s.msg)
        })
        .await?,
        route(bus, sender(Route::Tf), topics::VEHICLE_STATE, move |s: &Received<VehicleState>| TfMessage {
            transforms: vec![convert::ego_transform(s.header.stamp_sim_ns, &f2, &s.msg)],
        })
        .await?,
        route(bus, sender(Route::Objects), topics::OBJECTS, move |o: &Received<GroundTruthObjects>| {
            convert::ground_truth_markers(o.header.stamp_sim_ns, &f3, &o.msg)
        })
        .await?,
        route(bus, sender(Route::Detections), topics::PERCEPTION_OBJECTS, move |d: &Received<Detections>| {
            convert::detection_markers(d.header.stamp_sim_ns, &f4, &d.msg)
        })
        .await?,
        route(bus, sender(Route::Clock), topics::SIM_CLOCK, |c: &Received<SimClock>| {
            convert::clock(c.header.stamp_sim_ns)
        })
        .await?,
        route(bus, sender(Route::AccStatus), topics::ACC_STATUS, |a: &Received<AccStatus>| convert::acc_status(&a.msg))
            .await?,
    ];
    Ok(subs.into_iter().flatten().collect())
}

/// The entry of `route` in `config`, for callers that print the mapping.
pub fn describe(config: &Ros2Config) -> Vec<(Route, Entry)> {
    config.routes.iter().map(|(r, e)| (*r, e.clone())).collect()
}
