//! The typed bus over a Zenoh session.
//!
//! A [`Bus`] wraps one `zenoh::Session` with the [`TopicMap`] in force and the node's name. It
//! declares typed publishers and subscribers by topic (never by key string), attaches the
//! QoS the topic map gives, declares the node's liveliness token, and keeps statistics for
//! every subscription.

mod cadence;
mod error;
pub mod faults;
mod follow;
mod frame_copies;
mod frame_publisher;
mod namesake;
mod open;
mod publisher;
mod replay;
mod stats;
mod subscriber;

use std::sync::Arc;

pub(crate) use error::zerr;
pub use error::{without_source_locations, zenoh_message, BusError};
pub use faults::NodeClock;
pub use follow::{Following, FOLLOW_SWITCH_AFTER};
pub use frame_publisher::{FramePublisher, FrameSent};
pub use open::{open_session, SLOW_OPEN};
pub use publisher::{is_foreign, Publisher};
pub use replay::{is_replayed, replayed_name, REPLAY_SUFFIX};
pub use stats::{StatsSnapshot, TopicStats};
pub use subscriber::{
    Arrivals, CallbackSubscriber, Declared, FrameSample, FrameSubscriber, Received, Subscriber, Subscription,
};

use crate::config::{FaultProfile, TopicMap};
use crate::msg::{CameraFrame, Message};
use crate::topics::TopicDef;

/// The longest a session may take to close. A session closes in milliseconds; what could
/// hold it longer (a peer that stopped answering) must not hold up a node's exit.
pub const CLOSE_TIMEOUT: std::time::Duration = std::time::Duration::from_secs(2);

/// A node's connection to the system: session, topic map, node name and liveliness token.
pub struct Bus {
    session: zenoh::Session,
    /// The low-latency session for the topics whose QoS says so; None: all on `session`.
    low_latency: Option<zenoh::Session>,
    topics: Arc<TopicMap>,
    node: String,
    /// Faults injected into what this node receives (`--faults`); None: none, at no cost.
    faults: Option<Arc<FaultProfile>>,
    /// The node's simulated now: releases messages the faults hold back.
    clock: Arc<NodeClock>,
    /// The statistics of every subscription declared here (reported with faults on).
    inputs: Arc<parking_lot::Mutex<Vec<std::sync::Weak<TopicStats>>>>,
    /// The node's liveliness token once announced ([`Bus::announce`]).
    token: tokio::sync::Mutex<Option<zenoh::liveliness::LivelinessToken>>,
    /// Publishers declared from now on block rather than drop ([`Bus::keep_every_message`]).
    lossless: std::sync::atomic::AtomicBool,
}

impl Bus {
    /// Opens a Zenoh session with `config` and joins as `node`.
    pub async fn open(config: zenoh::Config, topics: TopicMap, node: &str) -> Result<Bus, BusError> {
        let session = open_session(config, "open session").await?;
        Bus::from_session(session, topics, node).await
    }

    /// A node process's bus: the connection and topic flags, and the faults `--faults` names
    /// injected into the node's inputs. Not yet announced: declare the node's subscriptions,
    /// then call [`Bus::announce`]. The simulator in lockstep starts stepping once it sees the
    /// nodes it waits for, so a node seen before it listens would miss the first steps.
    pub async fn open_node(
        connect: &crate::config::ConnectArgs,
        faults: &crate::config::FaultArgs,
        node: &str,
    ) -> Result<Bus, BusError> {
        let profile = faults.profile()?;
        let main = connect.zenoh_config()?;
        let low_latency = connect.low_latency_config(&main)?;
        let mut bus = Bus::join(main, low_latency, connect.topic_map()?, node).await?;
        if let Some(p) = profile {
            bus.inject_faults(p);
        }
        Ok(bus)
    }

    /// Opens the main session with `main` and, given its config, the low-latency session
    /// (`ConnectArgs::low_latency_config`), and joins as `node`, announced.
    pub async fn open_sessions(
        main: zenoh::Config,
        low_latency: Option<zenoh::Config>,
        topics: TopicMap,
        node: &str,
    ) -> Result<Bus, BusError> {
        let bus = Bus::join(main, low_latency, topics, node).await?;
        bus.announce().await?;
        Ok(bus)
    }

    /// Opens the sessions as [`Bus::open_sessions`] does, not yet announced.
    async fn join(
        main: zenoh::Config,
        low_latency: Option<zenoh::Config>,
        topics: TopicMap,
        node: &str,
    ) -> Result<Bus, BusError> {
        let session = open_session(main, "open session").await?;
        let low_latency = match low_latency {
            Some(mut c) => {
                let own: Vec<String> = session.info().locators().await.iter().map(|l| l.to_string()).collect();
                crate::config::dial_own_main(&mut c, &own)?;
                Some(open_session(c, "open the low-latency session").await?)
            }
            None => None,
        };
        Bus::unannounced(session, low_latency, topics, node)
    }

    /// Joins with an already-open session (tests hand in a loopback session): every topic on it.
    pub async fn from_session(session: zenoh::Session, topics: TopicMap, node: &str) -> Result<Bus, BusError> {
        Bus::from_sessions(session, None, topics, node).await
    }

    /// Joins with already-open sessions: the main one, and the one for the topics whose QoS
    /// names the low-latency session. Announced at once.
    pub async fn from_sessions(
        session: zenoh::Session,
        low_latency: Option<zenoh::Session>,
        topics: TopicMap,
        node: &str,
    ) -> Result<Bus, BusError> {
        let bus = Bus::unannounced(session, low_latency, topics, node)?;
        bus.announce().await?;
        Ok(bus)
    }

    fn unannounced(
        session: zenoh::Session,
        low_latency: Option<zenoh::Session>,
        topics: TopicMap,
        node: &str,
    ) -> Result<Bus, BusError> {
        topics.node_key(node)?;
        let low_latency_zid = low_latency.as_ref().map(|s| s.zid().to_string());
        tracing::info!(node, zid = %session.zid(), ?low_latency_zid, namespace = topics.namespace(), "joined the bus");
        Ok(Bus {
            session,
            low_latency,
            topics: Arc::new(topics),
            node: node.to_string(),
            faults: None,
            clock: Arc::new(NodeClock::default()),
            inputs: Arc::default(),
            token: tokio::sync::Mutex::new(None),
            lossless: std::sync::atomic::AtomicBool::new(false),
        })
    }

    /// Declares the node's liveliness token (`nodes/<name>`), once; later calls do nothing.
    /// A token of the same name already alive in the namespace is warned of (see `namesake`).
    /// Call it once the node's subscriptions are declared: it is how `slipstream top` lists
    /// the node and how the simulator in lockstep knows the node listens. Declarations from
    /// one session travel in order, so whoever sees the token has seen those subscriptions.
    pub async fn announce(&self) -> Result<(), BusError> {
        let mut token = self.token.lock().await;
        if token.is_none() {
            let key = self.topics.node_key(&self.node)?;
            if namesake::namesakes(&self.session, &key).await > 0 {
                tracing::warn!("{}", namesake::taken(&self.node, self.topics.namespace()));
            }
            let declared = self.session.liveliness().declare_token(key.clone()).await;
            *token = Some(declared.map_err(zerr(format!("declare liveliness token {key}")))?);
        }
        Ok(())
    }

    /// The same sessions and node with its topics under `<namespace>/<sub>`: one process
    /// serving several namespaces (the simulator with one per controlled vehicle) publishes and
    /// subscribes in each through its scope. The scope shares the node's faults, clock and
    /// input statistics; its liveliness stays the node's own (a scope is never announced).
    pub fn scoped(&self, sub: &str) -> Result<Bus, BusError> {
        let joined = match (self.topics.namespace(), sub.trim_matches('/')) {
            (ns, "") => ns.to_string(),
            ("", sub) => sub.to_string(),
            (ns, sub) => format!("{ns}/{sub}"),
        };
        let topics = (*self.topics).clone().with_namespace(&joined)?;
        Ok(Bus {
            session: self.session.clone(),
            low_latency: self.low_latency.clone(),
            topics: Arc::new(topics),
            node: self.node.clone(),
            faults: self.faults.clone(),
            clock: self.clock.clone(),
            inputs: self.inputs.clone(),
            token: tokio::sync::Mutex::new(None),
            lossless: std::sync::atomic::AtomicBool::new(self.lossless.load(std::sync::atomic::Ordering::SeqCst)),
        })
    }

    /// Injects `profile`'s faults into every subscription declared from now on (a node's
    /// inputs; tools and observers never call this). Logged, so a run with faults says so.
    pub fn inject_faults(&mut self, profile: FaultProfile) {
        let here: Vec<&str> =
            profile.topics.keys().filter(|t| profile.at(**t, &self.node).is_some()).map(|t| t.name()).collect();
        tracing::warn!(node = %self.node, on = ?here, "injecting faults: {}", profile.summary());
        self.faults = Some(Arc::new(profile));
        self.report_inputs();
    }

    /// Publishes the statistics of this node's subscriptions once a second (JSON on
    /// `nodes/<name>/inputs`), so `slipstream top` shows injected and real losses apart.
    /// Only with faults on: without them nothing is published.
    fn report_inputs(&self) {
        let Ok(handle) = tokio::runtime::Handle::try_current() else { return };
        let Ok(key) = self.topics.node_inputs_key(&self.node) else { return };
        let (session, registry, node) = (self.session.clone(), Arc::downgrade(&self.inputs), self.node.clone());
        handle.spawn(async move {
            let mut tick = tokio::time::interval(std::time::Duration::from_secs(1));
            loop {
                tick.tick().await;
                let Some(registry) = registry.upgrade() else { break };
                let inputs: Vec<StatsSnapshot> =
                    registry.lock().iter().filter_map(std::sync::Weak::upgrade).map(|s| s.snapshot()).collect();
                let body = serde_json::json!({ "node": node, "inputs": inputs }).to_string();
                let put =
                    session.put(&key, body).encoding(zenoh::bytes::Encoding::APPLICATION_JSON).attachment(node.clone());
                if put.await.is_err() {
                    break;
                }
            }
        });
    }

    fn register(&self, stats: &Arc<TopicStats>) {
        self.inputs.lock().push(Arc::downgrade(stats));
    }

    /// The fault profile in force, if any.
    pub fn faults(&self) -> Option<&FaultProfile> {
        self.faults.as_deref()
    }

    /// The node's simulated now as its faults see it. A node that keeps time itself (the
    /// simulator) advances it; for the others it follows the stamps they receive.
    pub fn clock(&self) -> &Arc<NodeClock> {
        &self.clock
    }

    /// QoS and faults for a subscription to `topic` at this node.
    fn inlet(&self, topic: crate::topics::Topic) -> subscriber::Inlet {
        let faults = self.faults.as_ref().and_then(|p| {
            p.at(topic, &self.node)
                .map(|f| (faults::Model::new(f.clone(), p.seed, topic.name(), &self.node), self.clock.clone()))
        });
        let frames = topic.kind() == crate::msg::MessageKind::CameraFrame;
        let poll_periodic = frames && self.topics.camera.poll_before_frame;
        subscriber::Inlet { qos: self.topics.qos(topic), faults, poll_periodic }
    }

    /// The main session (priorities; frames, events, liveliness, raw keys).
    pub fn session(&self) -> &zenoh::Session {
        &self.session
    }

    /// The low-latency session, if this node has one.
    pub fn low_latency_session(&self) -> Option<&zenoh::Session> {
        self.low_latency.as_ref()
    }

    /// The session that carries `topic` here: the one its QoS names, the main one if this
    /// node has no low-latency session.
    fn session_for(&self, topic: crate::topics::Topic) -> &zenoh::Session {
        match (self.topics.qos(topic).session, &self.low_latency) {
            (crate::qos::SessionKind::LowLatency, Some(ll)) => ll,
            _ => &self.session,
        }
    }

    pub fn topics(&self) -> &TopicMap {
        &self.topics
    }

    pub fn node(&self) -> &str {
        &self.node
    }

    /// Publishers declared from now on block where their topic's QoS says drop. A node in
    /// lockstep (and the simulator in fast mode, which promises every message a realtime run
    /// publishes) calls this: the loop waits for its slowest participant anyway, while a message
    /// dropped on a link whose transmit task ran late (a loaded machine) changes the run: a
    /// controller answers without its step's state, an observer judges a trace with a gap,
    /// and the same scenario no longer repeats to the last digit. In realtime the QoS stands:
    /// a slow subscriber must not hold up the loop.
    pub fn keep_every_message(&self) {
        self.lossless.store(true, std::sync::atomic::Ordering::SeqCst);
    }

    /// The topic map publishers are declared with: the configured one, or its lossless form.
    fn publishing_map(&self) -> std::borrow::Cow<'_, TopicMap> {
        match self.lossless.load(std::sync::atomic::Ordering::SeqCst) {
            true => std::borrow::Cow::Owned(self.topics.lossless()),
            false => std::borrow::Cow::Borrowed(&*self.topics),
        }
    }

    /// A typed publisher on `def`'s key with its configured QoS.
    pub async fn publisher<M: Message>(&self, def: TopicDef<M>) -> Result<Publisher<M>, BusError> {
        Publisher::declare(self.session_for(def.topic), &self.publishing_map(), def.topic, &self.node).await
    }

    /// A camera-frame publisher (`def`: camera/front or camera/narrow): renders straight into
    /// shared memory when it can.
    pub async fn frame_publisher(&self, def: TopicDef<CameraFrame>) -> Result<FramePublisher, BusError> {
        FramePublisher::declare(&self.session, &self.publishing_map(), def.topic, &self.node).await
    }

    /// A typed subscriber with the topic's configured delivery (latest-only or a queue).
    /// For camera frames prefer [`Bus::frame_subscriber`], which does not copy the pixels.
    pub async fn subscriber<M>(&self, def: TopicDef<M>) -> Result<Subscriber<M>, BusError>
    where
        M: Message + serde::de::DeserializeOwned + Clone + Send + 'static,
    {
        let sub = Subscriber::declare(
            self.session_for(def.topic),
            self.topics.read_key(def.topic),
            def.topic.name(),
            self.inlet(def.topic),
        )
        .await?;
        self.register(sub.stats());
        Ok(sub)
    }

    /// A camera-frame subscriber (`def`: camera/front or camera/narrow): frames are read in
    /// place (shared memory on one host).
    pub async fn frame_subscriber(&self, def: TopicDef<CameraFrame>) -> Result<FrameSubscriber, BusError> {
        let topic = def.topic;
        let sub = FrameSubscriber::declare(&self.session, self.topics.read_key(topic), topic.name(), self.inlet(topic))
            .await?;
        self.register(sub.stats());
        Ok(sub)
    }

    /// Calls `handler` with every well-formed message of `def`, on Zenoh's receive thread
    /// (lowest latency; keep the handler short).
    pub async fn subscribe_with<M, F>(&self, def: TopicDef<M>, handler: F) -> Result<CallbackSubscriber, BusError>
    where
        M: Message + serde::de::DeserializeOwned + Clone + Send + 'static,
        F: Fn(Received<M>) + Send + Sync + 'static,
    {
        let sub = CallbackSubscriber::declare(
            self.session_for(def.topic),
            self.topics.read_key(def.topic),
            def.topic.name(),
            self.inlet(def.topic),
            handler,
        )
        .await?;
        self.register(sub.stats());
        Ok(sub)
    }

    /// Calls `handler` with every valid camera frame on Zenoh's receive thread (zero-copy,
    /// no inbox): for consumers that queue or hand frames off themselves, such as a recorder.
    pub async fn subscribe_frames_with<F>(
        &self,
        def: TopicDef<CameraFrame>,
        handler: F,
    ) -> Result<CallbackSubscriber, BusError>
    where
        F: Fn(FrameSample) + Send + Sync + 'static,
    {
        let topic = def.topic;
        let sub = CallbackSubscriber::declare_frames(
            &self.session,
            self.topics.read_key(topic),
            topic.name(),
            self.inlet(topic),
            handler,
        )
        .await?;
        self.register(sub.stats());
        Ok(sub)
    }

    /// Names of the nodes alive in this namespace (their liveliness tokens).
    pub async fn nodes_alive(&self) -> Result<Vec<String>, BusError> {
        let selector = self.topics.nodes_selector();
        let replies = self
            .session
            .liveliness()
            .get(selector.clone())
            .timeout(std::time::Duration::from_secs(2))
            .await
            .map_err(zerr(format!("liveliness get {selector}")))?;
        let prefix = selector.as_str().trim_end_matches("**").to_string();
        let mut names = Vec::new();
        while let Ok(reply) = replies.recv_async().await {
            if let Ok(sample) = reply.result() {
                let key = sample.key_expr().as_str();
                names.push(key.strip_prefix(&prefix).unwrap_or(key).to_string());
            }
        }
        names.sort();
        names.dedup();
        Ok(names)
    }

    /// Calls `handler` with every raw sample on `key` (any key expression), undecoded: for
    /// tools that look at keys whatever their type (`slipstream top`, `echo`). `latched` also
    /// fetches the last sample of latched publishers. Dropping the result undeclares.
    pub async fn subscribe_samples<F>(
        &self,
        key: zenoh::key_expr::OwnedKeyExpr,
        latched: bool,
        handler: F,
    ) -> Result<Declared, BusError>
    where
        F: Fn(zenoh::sample::Sample) + Send + Sync + 'static,
    {
        subscriber::declare_callback(&self.session, &key, latched, handler).await
    }

    /// Follows the liveliness tokens of every node in this namespace.
    pub async fn watch_nodes(&self) -> Result<NodesWatch, BusError> {
        let selector = self.topics.nodes_selector();
        let prefix = selector.as_str().trim_end_matches("**").to_string();
        let names = Arc::new(parking_lot::Mutex::new(std::collections::BTreeSet::new()));
        let set = names.clone();
        let subscriber = self
            .session
            .liveliness()
            .declare_subscriber(selector.clone())
            .history(true)
            .callback(move |sample| {
                let key = sample.key_expr().as_str();
                let name = key.strip_prefix(&prefix).unwrap_or(key).to_string();
                if sample.kind() == zenoh::sample::SampleKind::Put {
                    set.lock().insert(name);
                } else {
                    set.lock().remove(&name);
                }
            })
            .await
            .map_err(zerr(format!("liveliness subscriber {selector}")))?;
        Ok(NodesWatch { names, _subscriber: subscriber })
    }

    /// Follows one node's liveliness token: `is_alive()` turns true when the node is up and
    /// false when it leaves or its session dies.
    pub async fn watch_node(&self, name: &str) -> Result<NodeWatch, BusError> {
        let key = self.topics.node_key(name)?;
        let alive = Arc::new(std::sync::atomic::AtomicBool::new(false));
        let flag = alive.clone();
        let subscriber = self
            .session
            .liveliness()
            .declare_subscriber(key.clone())
            .history(true)
            .callback(move |sample| {
                let up = sample.kind() == zenoh::sample::SampleKind::Put;
                flag.store(up, std::sync::atomic::Ordering::SeqCst);
            })
            .await
            .map_err(zerr(format!("liveliness subscriber {key}")))?;
        Ok(NodeWatch { alive, _subscriber: subscriber })
    }

    /// Leaves the bus: undeclares everything and closes the sessions, each within
    /// [`CLOSE_TIMEOUT`]. Both are closed even when the first fails; the first error is returned.
    pub async fn close(self) -> Result<(), BusError> {
        let low_latency = match &self.low_latency {
            Some(ll) => ll.close().timeout(CLOSE_TIMEOUT).await.map_err(zerr("close the low-latency session")),
            None => Ok(()),
        };
        let main = self.session.close().timeout(CLOSE_TIMEOUT).await.map_err(zerr("close session"));
        low_latency.and(main)
    }

    /// Leaves the bus at the end of a node's or a tool's work: as [`Bus::close`], but a failure
    /// is logged, not returned. By then the work is done and its result (a verdict, a summary,
    /// a file) stands; the process's exit closes whatever Zenoh still held.
    pub async fn leave(self) {
        let node = self.node.clone();
        if let Err(e) = self.close().await {
            tracing::warn!(node, "leaving the bus: {e}");
        }
    }
}

/// One node's liveliness, as `Bus::watch_node` follows it.
pub struct NodeWatch {
    alive: Arc<std::sync::atomic::AtomicBool>,
    _subscriber: zenoh::pubsub::Subscriber<()>,
}

impl NodeWatch {
    pub fn is_alive(&self) -> bool {
        self.alive.load(std::sync::atomic::Ordering::SeqCst)
    }
}

/// The nodes alive in a namespace, as `Bus::watch_nodes` follows them.
pub struct NodesWatch {
    names: Arc<parking_lot::Mutex<std::collections::BTreeSet<String>>>,
    _subscriber: zenoh::pubsub::Subscriber<()>,
}

impl NodesWatch {
    /// The names alive now, sorted.
    pub fn names(&self) -> Vec<String> {
        self.names.lock().iter().cloned().collect()
    }
}
