//! slipstream-detect on the bus: camera/front (latest-only) + camera/front/info, with
//! camera/narrow + camera/narrow/info when the vehicle has that camera -> perception/objects,
//! one message per front frame processed, stamped with the frame's simulation time and naming
//! the frame's sequence number and publish time. The narrow camera's frame of the same
//! instant (same stamp) joins each front frame; without it the front frame is used alone.

use std::future::Future;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use serde::Serialize;

use super::rig::CameraRig;
use super::settings::DetectSettings;
use slipstream_contract::bus::{Bus, BusError, Following, FrameSample, FrameSubscriber, Publisher, Subscriber};
use slipstream_contract::msg::{CameraFrameRef, CameraInfo, Detections};
use slipstream_contract::node::reader_thread::{self, STOP_POLL};
use slipstream_contract::topics;

/// What a run did.
#[derive(Debug, Clone, Default, Serialize, serde::Deserialize)]
#[serde(default)]
pub struct DetectStats {
    pub frames: u64,
    /// Frames replaced by a newer one before they were read (latest-only delivery).
    pub skipped: u64,
    /// Frames that could not be used (undecodable JPEG, size unlike camera info).
    pub unusable: u64,
    pub detections: u64,
    /// Frames and camera infos from another publisher than the camera followed: not used.
    pub foreign_inputs: u64,
    /// Front frames detected together with the narrow camera's frame of the same instant.
    pub narrow_frames: u64,
    /// Front frames that came before any camera/front/info (not usable: the detector needs the
    /// camera's intrinsics). Many means the latched info never reached this node.
    pub without_info: u64,
    /// Front frames whose narrow frame did not come in time (with a narrow camera known).
    pub narrow_missing: u64,
    /// Wall time spent detecting, fusing and tracking (not waiting for frames), seconds.
    pub busy_s: f64,
}

/// A camera's latched info, from the publisher that named itself first.
struct InfoInput {
    sub: Subscriber<CameraInfo>,
    topic: &'static str,
    from: Following,
    known: Option<CameraInfo>,
}

impl InfoInput {
    fn new(sub: Subscriber<CameraInfo>, name: &'static str) -> InfoInput {
        InfoInput { sub, topic: name, from: Following::new(name), known: None }
    }

    /// Takes what arrived; true when the info changed.
    fn poll(&mut self) -> bool {
        let mut changed = false;
        while let Some(info) = self.sub.try_recv() {
            if self.from.accept(info.source.as_deref(), Instant::now()) && self.known.as_ref() != Some(&info.msg) {
                tracing::info!(topic = self.topic, width = info.msg.width, height = info.msg.height, "camera info");
                self.known = Some(info.msg);
                changed = true;
            }
        }
        changed
    }
}

/// Runs until `shutdown` completes, frames read and detected on a thread of its own
/// (`slipstream_contract::node::reader_thread`: why).
pub async fn run(
    bus: &Bus,
    settings: DetectSettings,
    shutdown: impl Future<Output = ()>,
) -> Result<DetectStats, BusError> {
    let inputs = Inputs {
        frames: bus.frame_subscriber(topics::CAMERA_FRONT).await?,
        narrow_frames: bus.frame_subscriber(topics::CAMERA_NARROW).await?,
        info: InfoInput::new(bus.subscriber(topics::CAMERA_FRONT_INFO).await?, "camera/front/info"),
        narrow_info: InfoInput::new(bus.subscriber(topics::CAMERA_NARROW_INFO).await?, "camera/narrow/info"),
        out: bus.publisher(topics::PERCEPTION_OBJECTS).await?,
    };
    // Seen once it listens: the simulator in lockstep sends the first frame when it sees us.
    bus.announce().await?;
    reader_thread::until_stopped(move |stop| inputs.run(settings, stop), shutdown).await
}

/// The detector's subscriptions and its publisher.
struct Inputs {
    frames: FrameSubscriber,
    narrow_frames: FrameSubscriber,
    info: InfoInput,
    narrow_info: InfoInput,
    out: Publisher<Detections>,
}

/// What the reader keeps from frame to frame.
struct Reading {
    stats: DetectStats,
    rig: Option<CameraRig>,
    waiting_logged: bool,
    /// One camera set: frames from the publisher that named itself first.
    frames_from: Following,
    narrow_from: Following,
    narrow_held: Option<FrameSample>,
}

impl Inputs {
    /// Reads frames until `stop` (a blocking loop: call it on a thread of its own).
    fn run(mut self, settings: DetectSettings, stop: &AtomicBool) -> Result<DetectStats, BusError> {
        let mut r = Reading {
            stats: DetectStats::default(),
            rig: None,
            waiting_logged: false,
            frames_from: Following::new("camera/front"),
            narrow_from: Following::new("camera/narrow"),
            narrow_held: None,
        };
        while !stop.load(Ordering::Relaxed) {
            let Some(sample) = self.frames.recv_blocking(STOP_POLL) else { continue };
            if r.frames_from.accept(sample.source().as_deref(), Instant::now()) {
                self.detect(&sample, &settings, &mut r)?;
            }
        }
        let mut stats = r.stats;
        stats.skipped = self.frames.stats().snapshot().skipped;
        stats.foreign_inputs = r.frames_from.rejected()
            + r.narrow_from.rejected()
            + self.info.from.rejected()
            + self.narrow_info.from.rejected();
        Ok(stats)
    }

    /// The camera info in force; waits briefly for the first one (latched: it comes soon after
    /// start, and the frame in hand is used then: a lockstep controller waits for its
    /// detections). None while there is none.
    fn front_info(&mut self, r: &mut Reading) -> Option<CameraInfo> {
        let changed = self.info.poll() | self.narrow_info.poll();
        if self.info.known.is_none() {
            if !r.waiting_logged {
                tracing::info!("waiting for camera/front/info before using frames");
                r.waiting_logged = true;
            }
            if let Some(i) = self.info.sub.recv_blocking(Duration::from_millis(500)) {
                if self.info.from.accept(i.source.as_deref(), Instant::now()) {
                    self.info.known = Some(i.msg);
                }
            }
            self.narrow_info.poll();
            self.info.known.as_ref()?;
            r.rig = None;
        }
        if changed {
            r.rig = None;
        }
        self.info.known.clone()
    }

    /// One front frame: its narrow partner, detection, tracking, the Detections message.
    fn detect(&mut self, sample: &FrameSample, settings: &DetectSettings, r: &mut Reading) -> Result<(), BusError> {
        let Some(front_info) = self.front_info(r) else {
            r.stats.without_info += 1;
            if r.stats.without_info.is_power_of_two() && r.stats.without_info >= 8 {
                tracing::warn!(frames = r.stats.without_info, "still no camera/front/info: frames are not used");
            }
            return Ok(());
        };
        let rig = r.rig.get_or_insert_with(|| CameraRig::new(&front_info, self.narrow_info.known.as_ref(), settings));
        let frame = sample.frame();
        let header = frame.header;
        let Some(rgb) = usable(&frame.msg, &front_info, header.seq, &mut r.stats) else { return Ok(()) };
        let narrow_sample = match rig.narrow() {
            Some(_) => {
                let wait = settings.narrow_wait();
                let found =
                    narrow_at(&self.narrow_frames, &mut r.narrow_held, &mut r.narrow_from, header.stamp_sim_ns, wait);
                r.stats.narrow_missing += found.is_none() as u64;
                found
            }
            None => None,
        };
        let narrow_frame = narrow_sample.as_ref().map(|s| s.frame());
        let narrow_rgb = match (&narrow_frame, rig.narrow()) {
            (Some(f), Some(i)) => usable(&f.msg, i, f.header.seq, &mut r.stats),
            _ => None,
        };
        r.stats.narrow_frames += narrow_rgb.is_some() as u64;
        let started = Instant::now();
        let detections = rig.update(&rgb, narrow_rgb.as_deref(), header.stamp_sim_ns as f64 / 1e9);
        r.stats.busy_s += started.elapsed().as_secs_f64();
        r.stats.frames += 1;
        r.stats.detections += detections.len() as u64;
        self.out.put(
            header.stamp_sim_ns,
            &Detections { frame_seq: header.seq, frame_stamp_pub_ns: header.stamp_pub_ns, detections },
        )?;
        Ok(())
    }
}

/// A frame's pixels as RGB8 when it has the size its camera's info states and decodes; else
/// counted and logged (the 1st, 2nd, 4th, 8th ... such frame: a stream of bad frames does not
/// flood the log).
fn usable<'a>(
    frame: &CameraFrameRef<'a>,
    info: &CameraInfo,
    seq: u64,
    stats: &mut DetectStats,
) -> Option<std::borrow::Cow<'a, [u8]>> {
    let why = if (frame.width, frame.height) != (info.width, info.height) {
        format!(
            "frame {seq} is {}x{}, its camera info says {}x{}: skipped",
            frame.width, frame.height, info.width, info.height
        )
    } else {
        match frame.to_rgb8() {
            Ok(rgb) => return Some(rgb),
            Err(e) => format!("undecodable frame {seq}: {e}"),
        }
    };
    stats.unusable += 1;
    if stats.unusable.is_power_of_two() {
        tracing::warn!(unusable = stats.unusable, "{why}");
    }
    None
}

/// The narrow camera's frame stamped `stamp_ns`: already in, or in within `wait` (the
/// settings' `narrow_wait_ms`); None when it does not come or a later one replaced it.
fn narrow_at(
    frames: &FrameSubscriber,
    held: &mut Option<FrameSample>,
    from: &mut Following,
    stamp_ns: u64,
    wait: Duration,
) -> Option<FrameSample> {
    let mut waited = false;
    loop {
        while let Some(s) = frames.try_recv() {
            if from.accept(s.source().as_deref(), Instant::now()) {
                *held = Some(s);
            }
        }
        match held.as_ref().map(|s| s.header().stamp_sim_ns) {
            Some(t) if t == stamp_ns => return held.take(),
            Some(t) if t > stamp_ns => return None,
            _ if waited => return None,
            _ => {}
        }
        waited = true;
        if let Some(s) = frames.recv_blocking(wait) {
            if from.accept(s.source().as_deref(), Instant::now()) {
                *held = Some(s);
            }
        }
    }
}
