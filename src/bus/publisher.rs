//! Typed publishers: seq and stamps in the header, QoS from the topic map, rate limit.

use std::marker::PhantomData;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};

use parking_lot::Mutex;
use zenoh::bytes::{Encoding, ZBytes};
use zenoh::shm::{GarbageCollect, PosixShmProviderBackend, ShmProvider, ShmProviderBuilder};
use zenoh::Wait;

use super::frame_copies::FrameCopies;
use super::{zerr, BusError};
use crate::config::{CameraSettings, TopicMap};
use crate::msg::{self, encode_into, frame_prefix, CameraFrame, CameraFrameRef, Header, ImageEncoding, Message};
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
    fn next_header(&self, stamp_sim_ns: u64) -> Option<Header> {
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

    fn send(&self, payload: impl Into<ZBytes>) -> Result<(), BusError> {
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
pub fn encoding_of(kind: msg::MessageKind) -> Encoding {
    Encoding::APPLICATION_OCTET_STREAM.with_schema(kind.encoding_schema())
}

/// What a frame publish did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FrameSent {
    pub header: Header,
    /// The frame went out in a shared-memory buffer (zero-copy for subscribers on this host).
    pub shared_memory: bool,
}

/// Publishes camera frames. With shared memory on (the default), the payload is allocated in
/// a shared-memory pool and the caller renders straight into it: subscribers on this host
/// read the very bytes the renderer wrote.
pub struct FramePublisher {
    inner: Publisher<CameraFrame>,
    shm: Option<ShmProvider<PosixShmProviderBackend>>,
    heap_fallbacks: AtomicU64,
    camera: CameraSettings,
    copies: FrameCopies,
    /// Raw pixels kept for the link copies while one has a reader (the payload has gone).
    scratch: Mutex<Vec<u8>>,
}

/// How long a dropped frame publisher's shared-memory pool outlives it at most: frames put
/// just before the drop are still on their way, and a subscriber that maps one after its pool
/// is gone loses it.
const SHM_LINGER: std::time::Duration = std::time::Duration::from_secs(2);

/// Set (under the write lock) once the process exits. Zenoh's shared-memory cleanup runs as
/// the process exits, from an exit handler; a lingering pool touched after it panics. Ours,
/// registered after Zenoh's (its cleanup is registered when the first pool is made) and so
/// run before it, waits for any linger thread inside a pool call to leave it; the threads then
/// let go of their pools without another call (that cleanup unlinks the segments).
static EXITING: std::sync::RwLock<bool> = std::sync::RwLock::new(false);

extern "C" fn stop_lingering() {
    *EXITING.write().unwrap_or_else(|e| e.into_inner()) = true;
}

impl Drop for FramePublisher {
    /// The pool lives on (in a thread of its own) until every buffer in it is back or
    /// SHM_LINGER has passed: dropped at once, it took the last frame or two of a run with it
    /// (`bench fanout`: 1-2 of 10 frames lost at 2 subscribers; a lockstep test waiting for
    /// every frame timed out now and then).
    fn drop(&mut self) {
        let Some(shm) = self.shm.take() else { return };
        static ON_EXIT: std::sync::Once = std::sync::Once::new();
        // SAFETY: registers a function without arguments that only takes a lock.
        ON_EXIT.call_once(|| unsafe {
            libc::atexit(stop_lingering);
        });
        let pool = self.camera.shm_pool_mib << 20;
        let linger = move || {
            let deadline = std::time::Instant::now() + SHM_LINGER;
            loop {
                let exiting = EXITING.read().unwrap_or_else(|e| e.into_inner());
                if *exiting {
                    std::mem::forget(shm);
                    return;
                }
                if std::time::Instant::now() >= deadline || shm.available() >= pool {
                    drop(shm);
                    return;
                }
                shm.garbage_collect();
                drop(exiting);
                std::thread::sleep(std::time::Duration::from_millis(20));
            }
        };
        if let Err(e) = std::thread::Builder::new().name("shm-linger".into()).spawn(linger) {
            tracing::debug!("shared-memory pool dropped at once: {e}");
        }
    }
}

impl FramePublisher {
    pub(super) async fn declare(
        session: &zenoh::Session,
        topics: &TopicMap,
        topic: Topic,
        node: &str,
    ) -> Result<Self, BusError> {
        let inner = Publisher::declare(session, topics, topic, node).await?;
        let shm = if topics.camera.shared_memory {
            match ShmProviderBuilder::default_backend(topics.camera.shm_pool_mib << 20).wait() {
                Ok(p) => Some(p),
                Err(e) => {
                    tracing::warn!("shared memory unavailable, frames go through the heap: {e}");
                    None
                }
            }
        } else {
            None
        };
        let copies = FrameCopies::declare(session, topics, topic, node).await?;
        Ok(FramePublisher {
            inner,
            shm,
            heap_fallbacks: AtomicU64::new(0),
            camera: topics.camera,
            copies,
            scratch: Mutex::new(Vec::new()),
        })
    }

    /// Publishes a frame whose `data_len` image bytes `fill` writes in place.
    pub fn put_with(
        &self,
        stamp_sim_ns: u64,
        width: u32,
        height: u32,
        encoding: ImageEncoding,
        data_len: usize,
        fill: impl FnOnce(&mut [u8]),
    ) -> Result<Option<FrameSent>, BusError> {
        if let Some(expected) = encoding.expected_len(width, height) {
            if expected != data_len {
                return Err(BusError::InvalidFrame(format!(
                    "{width}x{height} {encoding:?} needs {expected} bytes, got {data_len}"
                )));
            }
        }
        let Some(header) = self.inner.next_header(stamp_sim_ns) else {
            return Ok(None);
        };
        let prefix = frame_prefix(&header, width, height, encoding, data_len);
        let total = prefix.len() + data_len;
        // The header's publish stamp is taken when the frame is complete (allocated and
        // filled, e.g. rendered), as the wire format says: at publish time.
        let stamped = || {
            let now = Header { stamp_pub_ns: msg::wall_clock_ns(), ..header };
            let now_prefix = frame_prefix(&now, width, height, encoding, data_len);
            // A varint of a later clock has the same length for centuries; if not, the
            // prefix the buffer was laid out for stands.
            if now_prefix.len() == prefix.len() {
                (now, now_prefix)
            } else {
                (header, prefix.clone())
            }
        };
        // Raw pixels the link copies are made from, once the frame itself has gone out.
        let keep = encoding == ImageEncoding::Rgb8 && self.copies.wanted();
        let kept = |pixels: &[u8]| {
            if keep {
                let mut scratch = self.scratch.lock();
                scratch.clear();
                scratch.extend_from_slice(pixels);
            }
        };
        let copies = |header: &Header| {
            if keep {
                self.copies.publish(header, width, height, &self.scratch.lock());
            }
        };
        if let Some(shm) = &self.shm {
            match shm.alloc(total).with_policy::<GarbageCollect>().wait() {
                Ok(mut buf) => {
                    let bytes: &mut [u8] = &mut buf;
                    fill(&mut bytes[prefix.len()..]);
                    kept(&bytes[prefix.len()..]);
                    let (header, prefix) = stamped();
                    bytes[..prefix.len()].copy_from_slice(&prefix);
                    self.inner.send(buf)?;
                    copies(&header);
                    return Ok(Some(FrameSent { header, shared_memory: true }));
                }
                Err(e) => {
                    let n = self.heap_fallbacks.fetch_add(1, Ordering::Relaxed);
                    if n.is_power_of_two() {
                        tracing::warn!(
                            fallbacks = n + 1,
                            "shared-memory pool full ({e:?}), frame sent from the heap; raise camera.shm_pool_mib"
                        );
                    }
                }
            }
        }
        // Zeroed allocation (calloc): a large buffer comes as fresh zero pages from the OS,
        // so the renderer's writes are the only pass over it (no memset first).
        let mut buf = vec![0u8; total];
        fill(&mut buf[prefix.len()..]);
        kept(&buf[prefix.len()..]);
        let (header, prefix) = stamped();
        buf[..prefix.len()].copy_from_slice(&prefix);
        self.inner.send(buf)?;
        copies(&header);
        Ok(Some(FrameSent { header, shared_memory: false }))
    }

    /// Publishes an existing image (one copy of its bytes into the payload); a raw one's link
    /// copies too.
    pub fn put(&self, stamp_sim_ns: u64, frame: &CameraFrameRef<'_>) -> Result<Option<FrameSent>, BusError> {
        self.put_with(stamp_sim_ns, frame.width, frame.height, frame.encoding, frame.data.len(), |dst| {
            dst.copy_from_slice(frame.data)
        })
    }

    /// Publishes RGB8 pixels in the encoding the config chose (`camera.encoding`; raw is one
    /// copy into the payload: render with [`FramePublisher::put_with`] to avoid it), then the
    /// link copies that have a reader.
    pub fn put_rgb(
        &self,
        stamp_sim_ns: u64,
        width: u32,
        height: u32,
        rgb: &[u8],
    ) -> Result<Option<FrameSent>, BusError> {
        let encoding = self.encoding();
        if encoding == ImageEncoding::Rgb8 {
            // put_with sends the copies of raw frames.
            return self.put(stamp_sim_ns, &CameraFrameRef { width, height, encoding, data: rgb });
        }
        let data = msg::encode_pixels(rgb, width, height, encoding, self.camera.jpeg_quality)
            .map_err(BusError::InvalidFrame)?;
        let sent = self.put(stamp_sim_ns, &CameraFrameRef { width, height, encoding, data: &data })?;
        if let Some(sent) = &sent {
            if self.copies.wanted() {
                self.copies.publish(&sent.header, width, height, rgb);
            }
        }
        Ok(sent)
    }

    /// The encoding `put_rgb` uses.
    pub fn encoding(&self) -> ImageEncoding {
        self.camera.encoding.image_encoding()
    }

    /// Keys of the link copies this publisher offers (`camera.link_copies`).
    pub fn copy_keys(&self) -> Vec<String> {
        self.copies.keys()
    }

    /// Whether some subscriber reads a link copy now (copies are encoded only then).
    pub fn copies_wanted(&self) -> bool {
        self.copies.wanted()
    }

    /// Link copies sent so far, every encoding together.
    pub fn copies_sent(&self) -> u64 {
        self.copies.sent()
    }

    /// Frames that had to go through the heap because the pool was full.
    pub fn heap_fallbacks(&self) -> u64 {
        self.heap_fallbacks.load(Ordering::Relaxed)
    }

    pub fn uses_shared_memory(&self) -> bool {
        self.shm.is_some()
    }

    pub fn publisher(&self) -> &Publisher<CameraFrame> {
        &self.inner
    }
}
