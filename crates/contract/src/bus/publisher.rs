//! Typed publishers: seq and stamps in the header, QoS from the topic map, rate limit.

use std::marker::PhantomData;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};

use parking_lot::Mutex;
use zenoh::bytes::{Encoding, ZBytes};
use zenoh::Wait;

use super::{zerr, BusError};
use crate::config::TopicMap;
use crate::msg::{self, encode_into, Header, Message};
use crate::topics::Topic;

/// The Zenoh publisher underneath: plain, or an advanced one that keeps the last message for
/// late subscribers (latched topics).
enum Inner {
    Plain(zenoh::pubsub::Publisher<'static>),
    Latched(zenoh_ext::AdvancedPublisher<'static>),
}

/// Publishes one message type on one topic.
pub struct Publisher<M> {
    inner: Inner,
    topic: Topic,
    seq: AtomicU64,
    /// With max_rate_hz: the smallest step of simulation time between two messages sent.
    min_interval_ns: Option<u64>,
    last_sim_ns: Mutex<Option<u64>>,
    /// Size of the last encoded message, to allocate the next buffer once.
    size_hint: AtomicUsize,
    /// The node's name, sent as every sample's attachment (lockstep tells controllers apart
    /// by it).
    source: ZBytes,
    _msg: PhantomData<fn(&M)>,
}

impl<M: Message> Publisher<M> {
    pub(super) async fn declare(
        session: &zenoh::Session,
        topics: &TopicMap,
        topic: Topic,
        node: &str,
    ) -> Result<Self, BusError> {
        Self::declare_at(session, topics.key(topic), topics.qos(topic), topic, node).await
    }

    /// Declares the publisher of `topic`'s messages on `key` with `qos`.
    pub(super) async fn declare_at(
        session: &zenoh::Session,
        key: zenoh::key_expr::OwnedKeyExpr,
        qos: crate::qos::TopicQos,
        topic: Topic,
        node: &str,
    ) -> Result<Self, BusError> {
        let builder = session
            .declare_publisher(key.clone())
            .encoding(encoding_of(M::KIND))
            .priority(qos.priority.into())
            .express(qos.express)
            .congestion_control(qos.congestion_control.into())
            .reliability(qos.reliability.into());
        let inner = if qos.latched {
            use zenoh_ext::AdvancedPublisherBuilderExt;
            let cache = zenoh_ext::CacheConfig::default().max_samples(1);
            // Sequence numbers (miss detection) rather than timestamps order the cache, so
            // latching works whatever the Zenoh config says about timestamping.
            let latched = builder
                .cache(cache)
                .sample_miss_detection(zenoh_ext::MissDetectionConfig::default())
                .publisher_detection()
                .await
                .map_err(zerr(format!("declare publisher on {key}")))?;
            Inner::Latched(latched)
        } else {
            Inner::Plain(builder.await.map_err(zerr(format!("declare publisher on {key}")))?)
        };
        tracing::debug!(topic = topic.name(), %key, ?qos, "publisher declared");
        Ok(Publisher {
            inner,
            topic,
            seq: AtomicU64::new(0),
            min_interval_ns: qos.max_rate_hz.map(|hz| (1e9 / hz) as u64),
            last_sim_ns: Mutex::new(None),
            size_hint: AtomicUsize::new(64),
            source: ZBytes::from(node.to_string()),
            _msg: PhantomData,
        })
    }

    /// Stamps and sends `msg` as data of simulation time `stamp_sim_ns`. Returns the header
    /// sent, or None when the topic's max_rate_hz dropped it (judged on simulation time, so a
    /// fast or lockstep run keeps the same messages as a real-time one).
    pub fn put(&self, stamp_sim_ns: u64, msg: &M) -> Result<Option<Header>, BusError> {
        let Some(header) = self.next_header(stamp_sim_ns) else {
            return Ok(None);
        };
        let mut buf = Vec::with_capacity(self.size_hint.load(Ordering::Relaxed));
        encode_into(&mut buf, &header, msg);
        self.size_hint.store(buf.len(), Ordering::Relaxed);
        self.send(buf)?;
        Ok(Some(header))
    }

    /// Sends `msg` with a header made elsewhere (a frame's link copy carries its frame's).
    /// `msg` is any type of this publisher's kind (a borrowed frame for a frame publisher).
    pub(super) fn put_stamped<T: Message>(&self, header: &Header, msg: &T) -> Result<(), BusError> {
        debug_assert_eq!(T::KIND, M::KIND);
        let mut buf = Vec::with_capacity(self.size_hint.load(Ordering::Relaxed));
        encode_into(&mut buf, header, msg);
        self.size_hint.store(buf.len(), Ordering::Relaxed);
        self.send(buf)
    }

    /// A flag that follows whether any subscriber matches this publisher (kept current by a
    /// matching listener). A latched publisher's flag stays true.
    pub(super) async fn matching_flag(&self) -> Result<std::sync::Arc<std::sync::atomic::AtomicBool>, BusError> {
        let flag = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
        match &self.inner {
            Inner::Plain(p) => {
                let f = flag.clone();
                p.matching_listener()
                    .callback(move |s| f.store(s.matching(), Ordering::Relaxed))
                    .background()
                    .await
                    .map_err(zerr(format!("matching listener on {}", self.key())))?;
            }
            Inner::Latched(_) => flag.store(true, Ordering::Relaxed),
        }
        Ok(flag)
    }

    /// Allocates the next header, or None when rate-limited.
    pub(super) fn next_header(&self, stamp_sim_ns: u64) -> Option<Header> {
        if let Some(min) = self.min_interval_ns {
            let mut last = self.last_sim_ns.lock();
            if let Some(prev) = *last {
                if stamp_sim_ns >= prev && stamp_sim_ns - prev < min {
                    return None;
                }
            }
            *last = Some(stamp_sim_ns);
        }
        let seq = self.seq.fetch_add(1, Ordering::Relaxed);
        Some(Header { seq, stamp_sim_ns, stamp_pub_ns: msg::wall_clock_ns() })
    }

    pub(super) fn send(&self, payload: impl Into<ZBytes>) -> Result<(), BusError> {
        let sent = match &self.inner {
            Inner::Plain(p) => p.put(payload).attachment(self.source.clone()).wait(),
            Inner::Latched(p) => p.put(payload).attachment(self.source.clone()).wait(),
        };
        sent.map_err(zerr(format!("put on {}", self.key())))
    }

    pub fn topic(&self) -> Topic {
        self.topic
    }

    pub fn key(&self) -> &str {
        match &self.inner {
            Inner::Plain(p) => p.key_expr().as_str(),
            Inner::Latched(p) => p.key_expr().as_str(),
        }
    }

    /// The priority the publisher was declared with.
    pub fn priority(&self) -> zenoh::qos::Priority {
        match &self.inner {
            Inner::Plain(p) => p.priority(),
            Inner::Latched(p) => p.priority(),
        }
    }

    /// The congestion control the publisher was declared with.
    pub fn congestion_control(&self) -> zenoh::qos::CongestionControl {
        match &self.inner {
            Inner::Plain(p) => p.congestion_control(),
            Inner::Latched(p) => p.congestion_control(),
        }
    }

    /// Whether the publisher keeps its last message for late subscribers.
    pub fn is_latched(&self) -> bool {
        matches!(self.inner, Inner::Latched(_))
    }

    async fn matching(&self) -> bool {
        let status = match &self.inner {
            Inner::Plain(p) => p.matching_status().await,
            Inner::Latched(p) => p.matching_status().await,
        };
        status.map(|s| s.matching()).unwrap_or(false)
    }

    /// Waits until at least one subscriber matches, or the timeout passes. Returns whether one
    /// matched.
    pub async fn wait_for_subscriber(&self, timeout: std::time::Duration) -> bool {
        let deadline = tokio::time::Instant::now() + timeout;
        loop {
            if self.matching().await {
                return true;
            }
            if tokio::time::Instant::now() >= deadline {
                return false;
            }
            tokio::time::sleep(std::time::Duration::from_millis(10)).await;
        }
    }
}

/// The Zenoh encoding every sample of `kind` carries.
pub(super) fn encoding_of(kind: msg::MessageKind) -> Encoding {
    Encoding::APPLICATION_OCTET_STREAM.with_schema(kind.encoding_schema())
}

/// Whether a sample is not the loop's: on a key no topic maps to, and without the encoding
/// every slipstream message carries ([`encoding_of`]). ROS 2 messages that `slipstream ros2`
/// bridges into the default namespace (`0/clock/...`) or a user's own keys are such samples:
/// tools show them apart instead of counting them as malformed payloads, which are ours.
pub fn is_foreign(sample: &zenoh::sample::Sample, topics: &crate::TopicMap) -> bool {
    let ours = sample.encoding().schema().is_some_and(|s| s.as_slice().starts_with(b"slipstream/"));
    !ours && topics.topic_of(sample.key_expr()).is_none()
}
