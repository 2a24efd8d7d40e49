//! The camera-frame publisher: frames rendered straight into a shared-memory buffer (or the
//! heap when the pool is full or shared memory is off), with the link copies of other
//! encodings that readers ask for. A file of its own beside [`super::publisher`], which it
//! builds on, and [`super::frame_copies`], which builds on that.

use std::sync::atomic::{AtomicU64, Ordering};

use parking_lot::Mutex;
use zenoh::shm::{GarbageCollect, PosixShmProviderBackend, ShmProvider, ShmProviderBuilder};
use zenoh::Wait;

use super::frame_copies::FrameCopies;
use super::publisher::Publisher;
use super::BusError;
use crate::config::{CameraSettings, TopicMap};
use crate::msg::{self, frame_prefix, CameraFrame, CameraFrameRef, Header, ImageEncoding};
use crate::topics::Topic;

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
                return Err(BusError::InvalidFrame(crate::msg::PixelError::RawLength {
                    width,
                    height,
                    needed: expected,
                    got: data_len,
                }));
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
