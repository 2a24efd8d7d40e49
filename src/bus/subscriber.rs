//! Typed subscribers: latest-only or bounded-queue delivery that never blocks Zenoh.
//!
//! Zenoh calls our callback on its receive thread. The callback reads only the header (for
//! statistics: latency, gaps), then hands the sample to a small queue that drops the oldest
//! entry when full. Zenoh's own FIFO handler would instead block its thread when full, and
//! with it every other topic on the same link. Bodies are decoded by the reader, on its own
//! thread, when it asks for the message.

use std::collections::VecDeque;
use std::marker::PhantomData;
use std::sync::Arc;
use std::time::Duration;

use parking_lot::Mutex;
use serde::de::DeserializeOwned;
use serde::Deserialize;
use zenoh::sample::Sample;

use super::{zerr, BusError, TopicStats};
use crate::msg::{self, decode_header, DecodeError, Header, Message, MessageKind, Stamped};
use crate::qos::Delivery;

/// A received message, decoded.
#[derive(Debug, Clone, PartialEq)]
pub struct Received<M> {
    pub header: Header,
    pub msg: M,
}

/// A received payload whose header is known good; decode the body with [`BusSample::decode`],
/// borrowing from the payload (camera frames: no copy of the pixels).
pub struct BusSample {
    sample: Sample,
    header: Header,
    /// The payload joined into one buffer, only when Zenoh delivered it in fragments
    /// (a large message over the network): the one copy a fragmented payload costs.
    joined: Option<Vec<u8>>,
}

impl BusSample {
    fn new(sample: Sample, header: Header) -> Self {
        let payload = sample.payload();
        let joined = if payload.slices().nth(1).is_some() { Some(payload.to_bytes().into_owned()) } else { None };
        BusSample { sample, header, joined }
    }

    pub fn header(&self) -> &Header {
        &self.header
    }

    pub fn key(&self) -> &str {
        self.sample.key_expr().as_str()
    }

    /// The whole payload, contiguous.
    pub fn bytes(&self) -> &[u8] {
        match &self.joined {
            Some(v) => v,
            None => self.sample.payload().slices().next().unwrap_or(&[]),
        }
    }

    /// Decodes the body strictly; `T` may borrow from this sample.
    pub fn decode<'a, T: Message + Deserialize<'a>>(&'a self) -> Result<Stamped<T>, DecodeError> {
        msg::decode(self.bytes())
    }

    /// Whether the payload sits in shared memory (it came from a publisher on this host).
    pub fn is_shared_memory(&self) -> bool {
        self.sample.payload().as_shm().is_some()
    }

    /// Whether the payload had to be joined from fragments (one copy).
    pub fn was_joined(&self) -> bool {
        self.joined.is_some()
    }

    pub fn zenoh_sample(&self) -> &Sample {
        &self.sample
    }
}

struct SampleQueue {
    items: Mutex<VecDeque<(Sample, Header)>>,
    capacity: usize,
    notify: tokio::sync::Notify,
}

/// Reads the header of a payload for statistics (from the first slice when it holds it).
fn read_header(sample: &Sample, kind: MessageKind) -> Result<Header, DecodeError> {
    let payload = sample.payload();
    let first = payload.slices().next().unwrap_or(&[]);
    match decode_header(first, kind) {
        Ok((h, _)) => Ok(h),
        Err(DecodeError::Truncated { .. }) if payload.slices().nth(1).is_some() => {
            decode_header(&payload.to_bytes(), kind).map(|(h, _)| h)
        }
        Err(e) => Err(e),
    }
}

/// A subscription to one topic.
pub struct Subscriber<M> {
    _inner: zenoh::pubsub::Subscriber<()>,
    queue: Arc<SampleQueue>,
    stats: Arc<TopicStats>,
    key: String,
    _msg: PhantomData<fn() -> M>,
}

impl<M: Message> Subscriber<M> {
    pub(crate) async fn declare(
        session: &zenoh::Session,
        key: zenoh::key_expr::OwnedKeyExpr,
        name: &str,
        delivery: Delivery,
    ) -> Result<Self, BusError> {
        let stats = Arc::new(TopicStats::new(name));
        let queue = Arc::new(SampleQueue {
            items: Mutex::new(VecDeque::with_capacity(delivery.capacity())),
            capacity: delivery.capacity(),
            notify: tokio::sync::Notify::new(),
        });
        let (q, st) = (queue.clone(), stats.clone());
        let inner = session
            .declare_subscriber(key.clone())
            .callback(move |sample: Sample| {
                let header = match read_header(&sample, M::KIND) {
                    Ok(h) => h,
                    Err(e) => return st.on_decode_error(&e),
                };
                st.on_message(&header, sample.payload().len(), msg::wall_clock_ns());
                let mut items = q.items.lock();
                if items.len() >= q.capacity {
                    items.pop_front();
                    st.on_skipped();
                }
                items.push_back((sample, header));
                drop(items);
                q.notify.notify_one();
            })
            .await
            .map_err(zerr(format!("declare subscriber on {key}")))?;
        tracing::debug!(topic = name, %key, ?delivery, "subscriber declared");
        Ok(Subscriber { _inner: inner, queue, stats, key: key.to_string(), _msg: PhantomData })
    }

    /// The next sample with a good header, undecoded; waits for one.
    pub async fn recv_sample(&self) -> BusSample {
        loop {
            if let Some(s) = self.try_recv_sample() {
                return s;
            }
            self.queue.notify.notified().await;
        }
    }

    /// The next sample if one is waiting.
    pub fn try_recv_sample(&self) -> Option<BusSample> {
        let (sample, header) = self.queue.items.lock().pop_front()?;
        Some(BusSample::new(sample, header))
    }

    /// The next sample within `timeout`.
    pub async fn recv_sample_timeout(&self, timeout: Duration) -> Option<BusSample> {
        tokio::time::timeout(timeout, self.recv_sample()).await.ok()
    }

    /// Records a body that failed to decode (counted and logged, rate-limited).
    pub fn report_decode_error(&self, error: &DecodeError) {
        self.stats.on_decode_error(error);
    }

    pub fn stats(&self) -> &Arc<TopicStats> {
        &self.stats
    }

    pub fn key(&self) -> &str {
        &self.key
    }
}

impl<M: Message + DeserializeOwned> Subscriber<M> {
    /// The next well-formed message; malformed ones are counted, logged and skipped.
    pub async fn recv(&self) -> Received<M> {
        loop {
            let sample = self.recv_sample().await;
            if let Some(r) = self.decode_owned(&sample) {
                return r;
            }
        }
    }

    /// The next well-formed message within `timeout`.
    pub async fn recv_timeout(&self, timeout: Duration) -> Option<Received<M>> {
        tokio::time::timeout(timeout, self.recv()).await.ok()
    }

    /// A well-formed message if one is waiting.
    pub fn try_recv(&self) -> Option<Received<M>> {
        while let Some(sample) = self.try_recv_sample() {
            if let Some(r) = self.decode_owned(&sample) {
                return Some(r);
            }
        }
        None
    }

    fn decode_owned(&self, sample: &BusSample) -> Option<Received<M>> {
        match msg::decode::<M>(sample.bytes()) {
            Ok(Stamped { header, msg }) => Some(Received { header, msg }),
            Err(e) => {
                self.stats.on_decode_error(&e);
                None
            }
        }
    }
}

/// A subscription whose messages are decoded and handed to a function on Zenoh's receive
/// thread: no queue, no thread handoff. For small hot-path messages (speed, control) whose
/// handler is quick; a slow handler here delays every message on the same link.
pub struct CallbackSubscriber {
    _inner: zenoh::pubsub::Subscriber<()>,
    stats: Arc<TopicStats>,
}

impl CallbackSubscriber {
    pub(crate) async fn declare<M, F>(
        session: &zenoh::Session,
        key: zenoh::key_expr::OwnedKeyExpr,
        name: &str,
        handler: F,
    ) -> Result<Self, BusError>
    where
        M: Message + DeserializeOwned,
        F: Fn(Received<M>) + Send + Sync + 'static,
    {
        let stats = Arc::new(TopicStats::new(name));
        let st = stats.clone();
        let inner = session
            .declare_subscriber(key.clone())
            .callback(move |sample: Sample| {
                let payload = sample.payload();
                let bytes = payload.to_bytes();
                match msg::decode::<M>(&bytes) {
                    Ok(Stamped { header, msg }) => {
                        st.on_message(&header, bytes.len(), msg::wall_clock_ns());
                        handler(Received { header, msg });
                    }
                    Err(e) => st.on_decode_error(&e),
                }
            })
            .await
            .map_err(zerr(format!("declare subscriber on {key}")))?;
        Ok(CallbackSubscriber { _inner: inner, stats })
    }

    pub fn stats(&self) -> &Arc<TopicStats> {
        &self.stats
    }
}
