//! A detector of the user's own as one function, `detect(&Frame) -> Vec<Detection>`; [`run`]
//! keeps the rest of docs/node-contract.md: it reads camera/front latest-only (a frame replaced
//! before it was read is skipped, never queued), uses no frame before camera/front/info
//! (latched), answers every frame it used with one perception/objects message stamped with the
//! frame's simulation time and naming its sequence number and publish stamp (also when it found
//! nothing), and declares the liveliness token once it listens. Frames are read and detected
//! on a thread of its own, woken by Zenoh's receive thread directly, as slipstream-detect
//! does: detection is CPU work that must not hold an async worker.
//!
//! examples/own-nodes/src/bin/own-detector.rs is a whole node on it.

use std::future::Future;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use serde::Serialize;

use super::reader_thread::STOP_POLL;
use crate::bus::{Bus, BusError, FrameSample, FrameSubscriber, Publisher, Subscriber};
use crate::msg::{CameraInfo, Detection, Detections};
use crate::topics;

/// How long a frame waits for the first camera/front/info (latched: it comes soon after start).
const INFO_WAIT: Duration = Duration::from_millis(500);

/// One camera frame, its pixels as RGB8 (row-major, 3 bytes a pixel) and its camera.
#[derive(Debug)]
pub struct Frame<'a> {
    /// Simulation time of the frame, s.
    pub t_s: f64,
    pub seq: u64,
    pub rgb: &'a [u8],
    /// The camera's intrinsics and mount (camera/front/info).
    pub camera: &'a CameraInfo,
}

/// What a run did.
#[derive(Debug, Clone, Default, Serialize)]
pub struct DetectorStats {
    /// Frames detected and answered.
    pub frames: u64,
    /// Frames replaced by a newer one before they were read (latest-only delivery).
    pub skipped: u64,
    /// Frames that came before any camera/front/info, or did not decode or match its size.
    pub unusable: u64,
    pub detections: u64,
}

/// Runs `detect` as the loop's detector until `shutdown` completes (see the module doc).
pub async fn run(
    bus: &Bus,
    detect: impl FnMut(&Frame) -> Vec<Detection> + Send + 'static,
    shutdown: impl Future,
) -> Result<DetectorStats, BusError> {
    let reader = Reader {
        frames: bus.frame_subscriber(topics::CAMERA_FRONT).await?,
        info: bus.subscriber(topics::CAMERA_FRONT_INFO).await?,
        out: bus.publisher(topics::PERCEPTION_OBJECTS).await?,
        camera: None,
        stats: DetectorStats::default(),
    };
    // Listening now: the simulator in lockstep sends the first frame when it sees the token.
    bus.announce().await?;
    super::reader_thread::until_stopped(move |stop| reader.run(detect, stop), shutdown).await
}

/// The detector's subscriptions, its publisher and what it knows.
struct Reader {
    frames: FrameSubscriber,
    info: Subscriber<CameraInfo>,
    out: Publisher<Detections>,
    camera: Option<CameraInfo>,
    stats: DetectorStats,
}

impl Reader {
    /// Reads frames until `stop` (a blocking loop: call it on a thread of its own).
    fn run(
        mut self,
        mut detect: impl FnMut(&Frame) -> Vec<Detection>,
        stop: &AtomicBool,
    ) -> Result<DetectorStats, BusError> {
        while !stop.load(Ordering::Relaxed) {
            if let Some(sample) = self.frames.recv_blocking(STOP_POLL) {
                self.answer(&sample, &mut detect)?;
            }
        }
        self.stats.skipped = self.frames.stats().snapshot().skipped;
        Ok(self.stats)
    }

    /// The camera in force: the newest info, the first awaited briefly.
    fn camera(&mut self) -> Option<&CameraInfo> {
        while let Some(i) = self.info.try_recv() {
            self.camera = Some(i.msg);
        }
        if self.camera.is_none() {
            self.camera = self.info.recv_blocking(INFO_WAIT).map(|i| i.msg);
        }
        self.camera.as_ref()
    }

    /// One frame: decoded, detected, answered; or counted as unusable.
    fn answer(
        &mut self,
        sample: &FrameSample,
        detect: &mut impl FnMut(&Frame) -> Vec<Detection>,
    ) -> Result<(), BusError> {
        let frame = sample.frame();
        let header = frame.header;
        let Some(camera) = self.camera().cloned() else {
            self.unusable(header.seq, "came before any camera/front/info");
            return Ok(());
        };
        if (frame.msg.width, frame.msg.height) != (camera.width, camera.height) {
            self.unusable(header.seq, "has another size than its camera info states");
            return Ok(());
        }
        let Ok(rgb) = frame.msg.to_rgb8() else {
            self.unusable(header.seq, "does not decode");
            return Ok(());
        };
        let t_s = header.stamp_sim_ns as f64 / 1e9;
        let detections = detect(&Frame { t_s, seq: header.seq, rgb: &rgb, camera: &camera });
        self.stats.frames += 1;
        self.stats.detections += detections.len() as u64;
        let answer = Detections { frame_seq: header.seq, frame_stamp_pub_ns: header.stamp_pub_ns, detections };
        self.out.put(header.stamp_sim_ns, &answer)?;
        Ok(())
    }

    /// Counts an unusable frame; logs the 1st, 2nd, 4th, 8th ... (a stream of them does not
    /// flood the log).
    fn unusable(&mut self, seq: u64, why: &str) {
        self.stats.unusable += 1;
        if self.stats.unusable.is_power_of_two() {
            tracing::warn!(unusable = self.stats.unusable, "frame {seq} {why}: not used");
        }
    }
}
