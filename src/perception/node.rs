//! slipstream-detect on the bus: camera/front (latest-only) + camera/front/info, with
//! camera/narrow + camera/narrow/info when the vehicle has that camera -> perception/objects,
//! one message per front frame processed, stamped with the frame's simulation time and naming
//! the frame's sequence number and publish time. The narrow camera's frame of the same
//! instant (same stamp) joins each front frame; without it the front frame is used alone.

use std::future::Future;
use std::time::{Duration, Instant};

use serde::Serialize;

use super::detector::DetectorParams;
use super::rig::CameraRig;
use crate::bus::{Bus, BusError, Following, FrameSample, FrameSubscriber, Subscriber};
use crate::msg::{CameraFrameRef, CameraInfo, Detections};
use crate::topics;

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
    /// Front frames whose narrow frame did not come in time (with a narrow camera known).
    pub narrow_missing: u64,
    /// Wall time spent detecting, fusing and tracking (not waiting for frames), seconds.
    pub busy_s: f64,
}

/// How long a front frame waits for the narrow camera's frame of the same instant (the
/// simulator publishes that one first, so it is normally in already).
const NARROW_WAIT: Duration = Duration::from_millis(50);

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

/// Runs until `shutdown` completes.
pub async fn run(
    bus: &Bus,
    params: DetectorParams,
    shutdown: impl Future<Output = ()>,
) -> Result<DetectStats, BusError> {
    let frames = bus.frame_subscriber(topics::CAMERA_FRONT).await?;
    let narrow_frames = bus.frame_subscriber(topics::CAMERA_NARROW).await?;
    let mut info = InfoInput::new(bus.subscriber(topics::CAMERA_FRONT_INFO).await?, "camera/front/info");
    let mut narrow_info = InfoInput::new(bus.subscriber(topics::CAMERA_NARROW_INFO).await?, "camera/narrow/info");
    let out = bus.publisher(topics::PERCEPTION_OBJECTS).await?;
    let mut stats = DetectStats::default();
    let mut rig: Option<CameraRig> = None;
    let mut waiting_logged = false;
    // One camera set: frames from the publisher that named itself first.
    let mut frames_from = Following::new("camera/front");
    let mut narrow_from = Following::new("camera/narrow");
    let mut narrow_held: Option<FrameSample> = None;
    tokio::pin!(shutdown);
    loop {
        let sample = tokio::select! {
            _ = &mut shutdown => break,
            s = frames.recv() => s,
        };
        if !frames_from.accept(sample.source().as_deref(), Instant::now()) {
            continue;
        }
        let changed = info.poll() | narrow_info.poll();
        if info.known.is_none() {
            if !waiting_logged {
                tracing::info!("waiting for camera/front/info before using frames");
                waiting_logged = true;
            }
            // The info is latched: it comes soon after start. The frame in hand is used then
            // (a lockstep controller waits for its detections).
            if let Some(i) = info.sub.recv_timeout(Duration::from_millis(500)).await {
                if info.from.accept(i.source.as_deref(), Instant::now()) {
                    info.known = Some(i.msg);
                }
            }
            narrow_info.poll();
            if info.known.is_none() {
                continue;
            }
            rig = None;
        }
        let front_info = info.known.as_ref().expect("camera info is known here");
        if changed || rig.is_none() {
            rig = Some(CameraRig::new(front_info, narrow_info.known.as_ref(), params));
        }
        let rig = rig.as_mut().expect("the rig is built here");
        let frame = sample.frame();
        let header = frame.header;
        let Some(rgb) = usable(&frame.msg, front_info, header.seq, &mut stats) else { continue };
        let narrow_sample = match rig.narrow() {
            Some(_) => {
                let found = narrow_at(&narrow_frames, &mut narrow_held, &mut narrow_from, header.stamp_sim_ns).await;
                stats.narrow_missing += found.is_none() as u64;
                found
            }
            None => None,
        };
        let narrow_frame = narrow_sample.as_ref().map(|s| s.frame());
        let narrow_rgb = match (&narrow_frame, rig.narrow()) {
            (Some(f), Some(i)) => usable(&f.msg, i, f.header.seq, &mut stats),
            _ => None,
        };
        stats.narrow_frames += narrow_rgb.is_some() as u64;
        let started = Instant::now();
        let detections = rig.update(&rgb, narrow_rgb.as_deref(), header.stamp_sim_ns as f64 / 1e9);
        stats.busy_s += started.elapsed().as_secs_f64();
        stats.frames += 1;
        stats.detections += detections.len() as u64;
        out.put(
            header.stamp_sim_ns,
            &Detections { frame_seq: header.seq, frame_stamp_pub_ns: header.stamp_pub_ns, detections },
        )?;
    }
    stats.skipped = frames.stats().snapshot().skipped;
    stats.foreign_inputs =
        frames_from.rejected() + narrow_from.rejected() + info.from.rejected() + narrow_info.from.rejected();
    Ok(stats)
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

/// The narrow camera's frame stamped `stamp_ns`: already in, or in within [`NARROW_WAIT`];
/// None when it does not come or a later one replaced it.
async fn narrow_at(
    frames: &FrameSubscriber,
    held: &mut Option<FrameSample>,
    from: &mut Following,
    stamp_ns: u64,
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
        if let Some(s) = frames.recv_timeout(NARROW_WAIT).await {
            if from.accept(s.source().as_deref(), Instant::now()) {
                *held = Some(s);
            }
        }
    }
}
