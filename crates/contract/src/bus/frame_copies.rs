//! Link copies of camera frames: each frame again, in another encoding, on
//! `<frames key>/@<encoding>` (camera/front/@lz4, camera/front/@jpeg), for readers across a link
//! that raw frames would not fit (docs/deployment.md, "Camera frames on a LAN").
//!
//! A copy is encoded only while some subscriber reads its key (a matching listener per copy),
//! so offering copies costs nothing until a reader chooses one with `camera.read`. A copy
//! carries its frame's header (same seq and stamps), so a reader can match frames across keys.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;

use super::publisher::Publisher;
use super::BusError;
use crate::config::{CameraEncoding, TopicMap};
use crate::msg::{self, CameraFrame, CameraFrameRef, Header};
use crate::topics::Topic;

struct Copy {
    encoding: CameraEncoding,
    publisher: Publisher<CameraFrame>,
    wanted: Arc<AtomicBool>,
}

/// The link copies of one frame topic.
pub(super) struct FrameCopies {
    copies: Vec<Copy>,
    jpeg_quality: u8,
    sent: AtomicU64,
    failures: AtomicU64,
}

impl FrameCopies {
    /// One publisher per encoding in `camera.link_copies` other than the frames' own.
    pub(super) async fn declare(
        session: &zenoh::Session,
        topics: &TopicMap,
        topic: Topic,
        node: &str,
    ) -> Result<FrameCopies, BusError> {
        let mut copies = Vec::new();
        for encoding in topics.camera.link_copies.iter().filter(|e| *e != topics.camera.encoding) {
            let key = topics.copy_key(topic, encoding);
            let publisher = Publisher::declare_at(session, key, topics.qos(topic), topic, node).await?;
            let wanted = publisher.matching_flag().await?;
            copies.push(Copy { encoding, publisher, wanted });
        }
        Ok(FrameCopies {
            copies,
            jpeg_quality: topics.camera.jpeg_quality,
            sent: AtomicU64::new(0),
            failures: AtomicU64::new(0),
        })
    }

    /// Whether any copy has a reader now.
    pub(super) fn wanted(&self) -> bool {
        self.copies.iter().any(|c| c.wanted.load(Ordering::Relaxed))
    }

    /// Encodes and sends the frame `header` stamped, from its RGB8 pixels, on every copy that
    /// has a reader. A copy that fails is counted and logged (rate-limited); the frame itself
    /// has gone out already.
    pub(super) fn publish(&self, header: &Header, width: u32, height: u32, rgb: &[u8]) {
        for copy in self.copies.iter().filter(|c| c.wanted.load(Ordering::Relaxed)) {
            let encoding = copy.encoding.image_encoding();
            let sent = msg::encode_pixels(rgb, width, height, encoding, self.jpeg_quality)
                .map_err(BusError::InvalidFrame)
                .and_then(|data| {
                    copy.publisher.put_stamped(header, &CameraFrameRef { width, height, encoding, data: &data })
                });
            if sent.is_ok() {
                self.sent.fetch_add(1, Ordering::Relaxed);
            }
            if let Err(e) = sent {
                let n = self.failures.fetch_add(1, Ordering::Relaxed) + 1;
                if n.is_power_of_two() {
                    tracing::warn!(copy = copy.publisher.key(), failures = n, "frame copy not sent: {e}");
                }
            }
        }
    }

    /// Copies sent so far (every encoding).
    pub(super) fn sent(&self) -> u64 {
        self.sent.load(Ordering::Relaxed)
    }

    /// Keys of the copies offered.
    pub(super) fn keys(&self) -> Vec<String> {
        self.copies.iter().map(|c| c.publisher.key().to_string()).collect()
    }
}
