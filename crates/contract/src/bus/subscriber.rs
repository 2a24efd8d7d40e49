//! Subscribers: every payload is validated on arrival, then handed over through a small
//! inbox that never blocks Zenoh.
//!
//! Zenoh calls our callback on its receive thread. The callback decodes the whole payload
//! (strictly: a bad body is a decode error, never a statistic), records the header in the
//! statistics (latency, gaps), then puts the message in an inbox that drops its oldest entry
//! when full (latest-only is an inbox of one). Zenoh's own FIFO handler would instead block
//! its thread when full, and with it every topic on the same link.
//!
//! - [`Subscriber<M>`] queues decoded messages.
//! - [`FrameSubscriber`] queues the received camera payload itself, validated as a
//!   [`CameraFrameRef`]; the reader decodes a view that borrows the pixels (zero-copy).
//! - [`CallbackSubscriber`] calls a function on the receive thread: no inbox, no handoff.

use std::collections::VecDeque;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use parking_lot::Mutex;
use serde::de::DeserializeOwned;
use zenoh::key_expr::OwnedKeyExpr;
use zenoh::sample::Sample;

use super::cadence::Cadence;
use super::faults::{Gate, Model, NodeClock};
use super::{zerr, BusError, TopicStats};
use crate::msg::{self, CameraFrameRef, DecodeError, Header, Message, Stamped};
use crate::qos::{Delivery, TopicQos};

/// A received message, decoded.
#[derive(Debug, Clone, PartialEq)]
pub struct Received<M> {
    pub header: Header,
    pub msg: M,
    /// The publishing node's name (the sample's attachment), when it sent one.
    pub source: Option<String>,
}

/// Bounded hand-over from Zenoh's thread to a reader: drops (and counts) the oldest. A task
/// waits on `notify`; a thread of its own waits on `arrived` (a futex wake, without a trip
/// through the async runtime's scheduler), and on a periodic stream polls `pushes` in a short
/// window around the next message instead of being woken for it ([`Cadence`]).
struct Inbox<T> {
    items: Mutex<VecDeque<T>>,
    capacity: usize,
    notify: tokio::sync::Notify,
    arrived: parking_lot::Condvar,
    /// The stream's cadence, when its reader polls around each message.
    cadence: Option<Mutex<Cadence>>,
    pushes: AtomicU64,
}

impl<T> Inbox<T> {
    fn new(delivery: Delivery, poll_periodic: bool) -> Self {
        Inbox {
            items: Mutex::new(VecDeque::with_capacity(delivery.capacity())),
            capacity: delivery.capacity(),
            notify: tokio::sync::Notify::new(),
            arrived: parking_lot::Condvar::new(),
            cadence: poll_periodic.then(|| Mutex::new(Cadence::default())),
            pushes: AtomicU64::new(0),
        }
    }

    fn push(&self, item: T, stats: &TopicStats) {
        let mut items = self.items.lock();
        if items.len() >= self.capacity {
            items.pop_front();
            stats.on_skipped();
        }
        items.push_back(item);
        drop(items);
        if let Some(cadence) = &self.cadence {
            cadence.lock().arrived(Instant::now());
            self.pushes.fetch_add(1, Ordering::Release);
        }
        self.notify.notify_one();
        self.arrived.notify_one();
    }

    fn try_pop(&self) -> Option<T> {
        self.items.lock().pop_front()
    }

    async fn pop(&self) -> T {
        loop {
            if let Some(item) = self.try_pop() {
                return item;
            }
            self.notify.notified().await;
        }
    }

    /// The next item within `timeout`, on a thread of its own: parked until a message comes
    /// or, on a periodic stream, until its window opens, then polling until the window closes.
    fn pop_blocking(&self, timeout: Duration) -> Option<T> {
        let deadline = Instant::now() + timeout;
        loop {
            let mut items = self.items.lock();
            if let Some(item) = items.pop_front() {
                return Some(item);
            }
            let now = Instant::now();
            if now >= deadline {
                return None;
            }
            // (A statement of its own: the guard must not live through the wait below.)
            let window = self.cadence.as_ref().and_then(|c| c.lock().window()).filter(|&(_, closes)| closes > now);
            match window {
                Some((opens, _)) if now < opens => {
                    self.arrived.wait_until(&mut items, opens.min(deadline));
                }
                Some((_, closes)) => {
                    let seen = self.pushes.load(Ordering::Acquire);
                    drop(items);
                    let until = closes.min(deadline);
                    while self.pushes.load(Ordering::Acquire) == seen && Instant::now() < until {
                        std::hint::spin_loop();
                    }
                }
                None => {
                    if self.arrived.wait_until(&mut items, deadline).timed_out() {
                        return items.pop_front();
                    }
                }
            }
        }
    }
}

/// Keeps a declared Zenoh subscriber (plain or advanced) alive; dropping it undeclares.
pub type Declared = Box<dyn std::any::Any + Send + Sync>;

/// Declares a Zenoh subscriber calling `callback`; for a latched topic an advanced subscriber
/// that first fetches the last message of every publisher, including ones that start later.
pub(crate) async fn declare_callback<F>(
    session: &zenoh::Session,
    key: &OwnedKeyExpr,
    latched: bool,
    callback: F,
) -> Result<Declared, BusError>
where
    F: Fn(Sample) + Send + Sync + 'static,
{
    let builder = session.declare_subscriber(key.clone());
    let declared: Declared = if latched {
        use zenoh_ext::AdvancedSubscriberBuilderExt;
        let history = zenoh_ext::HistoryConfig::default().detect_late_publishers().max_samples(1);
        Box::new(
            builder.history(history).callback(callback).await.map_err(zerr(format!("declare subscriber on {key}")))?,
        )
    } else {
        Box::new(builder.callback(callback).await.map_err(zerr(format!("declare subscriber on {key}")))?)
    };
    Ok(declared)
}

/// The newest simulated time that arrived on a subscription (before any injected fault), per
/// publishing node when faults are on: what a lockstep node waits for. Noted after the message
/// was handed on, so whoever sees it arrived also finds it delivered (unless a fault held it).
pub struct Arrivals {
    /// Newest stamp + 1 (0: nothing yet).
    newest: std::sync::atomic::AtomicU64,
    by_source: Option<Mutex<std::collections::BTreeMap<String, u64>>>,
    notify: tokio::sync::Notify,
}

impl Arrivals {
    fn new(per_source: bool) -> Self {
        Arrivals {
            newest: std::sync::atomic::AtomicU64::new(0),
            by_source: per_source.then(Default::default),
            notify: tokio::sync::Notify::new(),
        }
    }

    fn note(&self, stamp_ns: u64, source: Option<String>) {
        self.newest.fetch_max(stamp_ns.saturating_add(1), std::sync::atomic::Ordering::AcqRel);
        if let (Some(map), Some(source)) = (&self.by_source, source) {
            let mut m = map.lock();
            let e = m.entry(source).or_insert(stamp_ns);
            *e = (*e).max(stamp_ns);
        }
        self.notify.notify_waiters();
    }

    /// Whether a message stamped `stamp_ns` or later has arrived.
    pub fn since(&self, stamp_ns: u64) -> bool {
        self.newest.load(std::sync::atomic::Ordering::Acquire) > stamp_ns
    }

    /// Whether a message stamped `stamp_ns` or later has arrived from `source` (known only with
    /// faults on; without them, whether one arrived from anyone).
    pub fn since_from(&self, source: &str, stamp_ns: u64) -> bool {
        match &self.by_source {
            Some(map) => map.lock().get(source).is_some_and(|t| *t >= stamp_ns),
            None => self.since(stamp_ns),
        }
    }

    /// Waits for the next arrival, or `timeout`; returns at once when `done()` already holds.
    pub async fn wait(&self, timeout: Duration, done: impl Fn() -> bool) {
        let notified = self.notify.notified();
        tokio::pin!(notified);
        notified.as_mut().enable();
        if done() {
            return;
        }
        let _ = tokio::time::timeout(timeout, notified).await;
    }
}

/// Where a subscription's samples enter the node: the topic's QoS and, with a fault profile,
/// the faults to inject and the node's clock.
pub(crate) struct Inlet {
    pub qos: TopicQos,
    pub faults: Option<(Model, Arc<NodeClock>)>,
    /// A reader thread polls in a window around each message of a periodic stream
    /// (`camera.poll_before_frame`).
    pub poll_periodic: bool,
}

/// Declares a subscriber that validates every sample with `accept`, records the good ones in
/// `stats` (and counts the bad ones there), and hands each accepted item to `deliver`, through
/// the inlet's faults when it has some.
async fn declare_accepting<T, A, D>(
    session: &zenoh::Session,
    key: &OwnedKeyExpr,
    inlet: Inlet,
    stats: Arc<TopicStats>,
    arrivals: Arc<Arrivals>,
    accept: A,
    deliver: D,
) -> Result<Declared, BusError>
where
    T: Clone + Send + 'static,
    A: Fn(Sample) -> Result<(Header, usize, T), DecodeError> + Send + Sync + 'static,
    D: Fn(T) + Send + Sync + 'static,
{
    let latched = inlet.qos.latched;
    match inlet.faults {
        None => {
            declare_callback(session, key, latched, move |sample: Sample| {
                let source = sample.attachment().and_then(|a| a.try_to_string().ok()).map(|s| s.into_owned());
                match accept(sample) {
                    Ok((header, len, item)) => {
                        stats.on_message_from(source.as_deref(), &header, len, msg::wall_clock_ns());
                        deliver(item);
                        arrivals.note(header.stamp_sim_ns, None);
                    }
                    Err(e) => stats.on_decode_error(&e),
                }
            })
            .await
        }
        Some((model, clock)) => {
            let gate = Gate::new(model, clock, stats.clone(), deliver);
            declare_callback(session, key, latched, move |sample: Sample| {
                let source = sample.attachment().and_then(|a| a.try_to_string().ok()).map(|s| s.into_owned());
                match accept(sample) {
                    Ok((header, len, item)) => {
                        stats.on_message_from(source.as_deref(), &header, len, msg::wall_clock_ns());
                        gate.arrive(&header, len, item);
                        arrivals.note(header.stamp_sim_ns, source);
                    }
                    Err(e) => stats.on_decode_error(&e),
                }
            })
            .await
        }
    }
}

/// Decodes a payload into an owned message.
fn accept_decoded<M: Message + DeserializeOwned>(sample: Sample) -> Result<(Header, usize, Received<M>), DecodeError> {
    let payload = sample.payload();
    let bytes = payload.to_bytes();
    let Stamped { header, msg } = msg::decode::<M>(&bytes)?;
    let source = sample.attachment().and_then(|a| a.try_to_string().ok()).map(|s| s.into_owned());
    Ok((header, bytes.len(), Received { header, msg, source }))
}

/// A received camera payload, validated; [`FrameSample::frame`] borrows the pixels from it.
#[derive(Clone)]
pub struct FrameSample {
    sample: Sample,
    header: Header,
    /// The payload joined into one buffer, only when Zenoh delivered it in fragments (a large
    /// frame over the network): the one copy such a frame costs on the way in. Shared, so that
    /// a clone of the sample (a reader keeping the frame) copies no pixels.
    joined: Option<std::sync::Arc<Vec<u8>>>,
    /// Wall clock (ns since the epoch) when Zenoh handed the sample to this node.
    arrived_ns: u64,
}

impl FrameSample {
    pub fn header(&self) -> &Header {
        &self.header
    }

    /// The whole payload, contiguous.
    pub fn bytes(&self) -> &[u8] {
        match &self.joined {
            Some(v) => v,
            None => self.sample.payload().slices().next().unwrap_or(&[]),
        }
    }

    /// The frame, its pixels borrowed from the payload (shared memory on one host).
    pub fn frame(&self) -> Stamped<CameraFrameRef<'_>> {
        match msg::decode::<CameraFrameRef>(self.bytes()) {
            Ok(f) => f,
            // Validated on arrival and immutable since: decoding the same bytes again cannot
            // fail.
            Err(e) => unreachable!("a validated frame failed to decode: {e}"),
        }
    }

    /// Whether the payload sits in shared memory (published by a process on this host).
    pub fn is_shared_memory(&self) -> bool {
        self.sample.payload().as_shm().is_some()
    }

    /// The publishing node's name (the sample's attachment), when it sent one.
    pub fn source(&self) -> Option<String> {
        self.sample.attachment().and_then(|a| a.try_to_string().ok()).map(|s| s.into_owned())
    }

    /// Wall clock (ns since the epoch) when Zenoh's receive thread handed the frame over: a
    /// reader's `now - arrived_ns` is what the hand-off to it took.
    pub fn arrived_ns(&self) -> u64 {
        self.arrived_ns
    }

    /// Whether the payload had to be joined from fragments (one copy).
    pub fn was_joined(&self) -> bool {
        self.joined.is_some()
    }
}

/// Validates a camera payload as a frame (joining fragments if Zenoh delivered it in pieces).
fn accept_frame(sample: Sample) -> Result<(Header, usize, FrameSample), DecodeError> {
    let payload = sample.payload();
    let joined = if payload.slices().nth(1).is_some() {
        Some(std::sync::Arc::new(payload.to_bytes().into_owned()))
    } else {
        None
    };
    let len = payload.len();
    let bytes = match &joined {
        Some(v) => v.as_slice(),
        None => payload.slices().next().unwrap_or(&[]),
    };
    let header = msg::decode::<CameraFrameRef>(bytes)?.header;
    Ok((header, len, FrameSample { sample, header, joined, arrived_ns: msg::wall_clock_ns() }))
}

/// A subscription to one topic whose messages wait in an inbox until the reader takes them.
pub struct Subscription<T> {
    _inner: Declared,
    inbox: Arc<Inbox<T>>,
    stats: Arc<TopicStats>,
    arrivals: Arc<Arrivals>,
    key: String,
}

/// Decoded messages of one topic.
pub type Subscriber<M> = Subscription<Received<M>>;

/// Camera frames, validated on arrival and read in place (zero-copy).
pub type FrameSubscriber = Subscription<FrameSample>;

impl<T: Clone + Send + 'static> Subscription<T> {
    async fn declare_with<F>(
        session: &zenoh::Session,
        key: OwnedKeyExpr,
        name: &str,
        inlet: Inlet,
        accept: F,
    ) -> Result<Self, BusError>
    where
        F: Fn(Sample) -> Result<(Header, usize, T), DecodeError> + Send + Sync + 'static,
    {
        let stats = Arc::new(TopicStats::new(name));
        let delivery = inlet.qos.delivery;
        let inbox = Arc::new(Inbox::new(delivery, inlet.poll_periodic));
        let arrivals = Arc::new(Arrivals::new(inlet.faults.is_some()));
        let (into, counted) = (inbox.clone(), stats.clone());
        let deliver = move |item| into.push(item, &counted);
        let faulted = inlet.faults.is_some();
        let inner = declare_accepting(session, &key, inlet, stats.clone(), arrivals.clone(), accept, deliver).await?;
        tracing::debug!(topic = name, %key, ?delivery, faulted, "subscriber declared");
        Ok(Subscription { _inner: inner, inbox, stats, arrivals, key: key.to_string() })
    }
}

impl<T> Subscription<T> {
    /// The next message; waits for one.
    pub async fn recv(&self) -> T {
        self.inbox.pop().await
    }

    /// The next message within `timeout`.
    pub async fn recv_timeout(&self, timeout: Duration) -> Option<T> {
        tokio::time::timeout(timeout, self.recv()).await.ok()
    }

    /// The next message within `timeout`, blocking the calling thread: for a reader on a
    /// thread of its own, woken by the receive thread directly (no async runtime between).
    /// Never call it from an async task.
    pub fn recv_blocking(&self, timeout: Duration) -> Option<T> {
        self.inbox.pop_blocking(timeout)
    }

    /// A message if one is waiting.
    pub fn try_recv(&self) -> Option<T> {
        self.inbox.try_pop()
    }

    pub fn stats(&self) -> &Arc<TopicStats> {
        &self.stats
    }

    /// What has arrived, before injected faults: a lockstep reader waits for its step's
    /// message to arrive, then takes what was delivered.
    pub fn arrivals(&self) -> &Arrivals {
        &self.arrivals
    }

    pub fn key(&self) -> &str {
        &self.key
    }
}

impl<M: Message + DeserializeOwned + Clone + Send + 'static> Subscription<Received<M>> {
    pub(crate) async fn declare(
        session: &zenoh::Session,
        key: OwnedKeyExpr,
        name: &str,
        inlet: Inlet,
    ) -> Result<Self, BusError> {
        Self::declare_with(session, key, name, inlet, accept_decoded::<M>).await
    }
}

impl Subscription<FrameSample> {
    pub(crate) async fn declare(
        session: &zenoh::Session,
        key: OwnedKeyExpr,
        name: &str,
        inlet: Inlet,
    ) -> Result<Self, BusError> {
        Self::declare_with(session, key, name, inlet, accept_frame).await
    }
}

/// A subscription whose messages are decoded and handed to a function on Zenoh's receive
/// thread: no inbox, no thread handoff. For small hot-path messages (speed, control) whose
/// handler is quick; a slow handler here delays every message on the same link.
pub struct CallbackSubscriber {
    _inner: Declared,
    stats: Arc<TopicStats>,
    arrivals: Arc<Arrivals>,
}

impl CallbackSubscriber {
    async fn declare_with<T, A, F>(
        session: &zenoh::Session,
        key: OwnedKeyExpr,
        name: &str,
        inlet: Inlet,
        accept: A,
        handler: F,
    ) -> Result<Self, BusError>
    where
        T: Clone + Send + 'static,
        A: Fn(Sample) -> Result<(Header, usize, T), DecodeError> + Send + Sync + 'static,
        F: Fn(T) + Send + Sync + 'static,
    {
        let stats = Arc::new(TopicStats::new(name));
        let arrivals = Arc::new(Arrivals::new(inlet.faults.is_some()));
        let inner = declare_accepting(session, &key, inlet, stats.clone(), arrivals.clone(), accept, handler).await?;
        Ok(CallbackSubscriber { _inner: inner, stats, arrivals })
    }

    pub(crate) async fn declare<M, F>(
        session: &zenoh::Session,
        key: OwnedKeyExpr,
        name: &str,
        inlet: Inlet,
        handler: F,
    ) -> Result<Self, BusError>
    where
        M: Message + DeserializeOwned + Clone + Send + 'static,
        F: Fn(Received<M>) + Send + Sync + 'static,
    {
        Self::declare_with(session, key, name, inlet, accept_decoded::<M>, handler).await
    }

    pub(crate) async fn declare_frames<F>(
        session: &zenoh::Session,
        key: OwnedKeyExpr,
        name: &str,
        inlet: Inlet,
        handler: F,
    ) -> Result<Self, BusError>
    where
        F: Fn(FrameSample) + Send + Sync + 'static,
    {
        Self::declare_with(session, key, name, inlet, accept_frame, handler).await
    }

    pub fn stats(&self) -> &Arc<TopicStats> {
        &self.stats
    }

    /// What has arrived, before injected faults (see [`Subscription::arrivals`]).
    pub fn arrivals(&self) -> &Arrivals {
        &self.arrivals
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bus::faults::{Gate, Model, NodeClock};
    use crate::config::{Loss, TopicFaults};

    /// A reader thread polling around each message of a periodic stream still gets every
    /// message in order, once, and still times out when the stream stops: polling changes
    /// when it is awake, never what it reads.
    #[test]
    fn a_polling_reader_gets_a_periodic_stream_whole_and_times_out_after_it() {
        for poll in [true, false] {
            let inbox = Arc::new(Inbox::new(Delivery::Queue(4), poll));
            let stats = TopicStats::new("test");
            let writer = {
                let inbox = inbox.clone();
                std::thread::spawn(move || {
                    for i in 0..20u32 {
                        std::thread::sleep(Duration::from_millis(12));
                        inbox.push(i, &stats);
                    }
                })
            };
            let got: Vec<u32> = (0..20).map_while(|_| inbox.pop_blocking(Duration::from_secs(5))).collect();
            writer.join().unwrap();
            assert_eq!(got, (0..20).collect::<Vec<_>>(), "poll={poll}");
            let waited = std::time::Instant::now();
            assert_eq!(inbox.pop_blocking(Duration::from_millis(30)), None, "poll={poll}");
            assert!(waited.elapsed() >= Duration::from_millis(30), "poll={poll}: returned before its timeout");
            assert_eq!(inbox.cadence.is_some(), poll);
        }
    }

    #[test]
    fn arrivals_say_what_arrived_from_whom() {
        let a = Arrivals::new(true);
        assert!(!a.since(0), "nothing yet");
        a.note(0, Some("acc".into()));
        assert!(a.since(0) && !a.since(1));
        a.note(50, Some("acc".into()));
        a.note(20, Some("other".into()));
        assert!(a.since(50) && !a.since(51));
        assert!(a.since_from("acc", 50) && !a.since_from("other", 21) && !a.since_from("nobody", 0));
        let plain = Arrivals::new(false);
        plain.note(7, None);
        assert!(plain.since_from("anyone", 7), "without faults: from anyone");
    }

    /// What the fault layer adds per message, off (an arrival noted) and on (a gate with delay
    /// and loss). A measurement, not a check: run with
    /// `cargo test --release --lib fault_layer_cost -- --ignored --nocapture` (docs/faults.md).
    #[test]
    #[ignore]
    fn fault_layer_cost_per_message() {
        const N: u64 = 5_000_000;
        let arrivals = Arrivals::new(false);
        let t = std::time::Instant::now();
        for i in 0..N {
            arrivals.note(std::hint::black_box(i), None);
        }
        let off_ns = t.elapsed().as_nanos() as f64 / N as f64;
        let clock = Arc::new(NodeClock::default());
        let stats = Arc::new(TopicStats::new("t"));
        let faults = TopicFaults { delay_ms: 20.0, loss: Some(Loss::Independent(0.1)), ..TopicFaults::default() };
        let gate = Gate::new(Model::new(faults, 1, "t", "n"), clock, stats, |x: u64| {
            std::hint::black_box(x);
        });
        let t = std::time::Instant::now();
        for i in 0..N {
            let h = Header { seq: i, stamp_sim_ns: i * 10_000_000, stamp_pub_ns: 0 };
            gate.arrive(&h, 64, i);
        }
        let on_ns = t.elapsed().as_nanos() as f64 / N as f64;
        println!("fault layer per message: off {off_ns:.1} ns (an arrival noted), on {on_ns:.1} ns (gate: 20 ms delay, 10 % loss)");
    }
}
