//! slipstream-detect on the bus: camera/front (latest-only) + camera/front/info ->
//! perception/objects, one message per frame processed, stamped with the frame's simulation
//! time and naming the frame's sequence number and publish time.

use std::future::Future;
use std::time::{Duration, Instant};

use serde::Serialize;

use super::detector::{Detector, DetectorParams};
use super::tracker::Tracker;
use crate::bus::{Bus, BusError, Following};
use crate::msg::{CameraInfo, Detections};
use crate::topics;

/// What a run did.
#[derive(Debug, Clone, Default, Serialize)]
pub struct DetectStats {
    pub frames: u64,
    /// Frames replaced by a newer one before they were read (latest-only delivery).
    pub skipped: u64,
    /// Frames that could not be used (undecodable JPEG, size unlike camera info).
    pub unusable: u64,
    pub detections: u64,
    /// Frames and camera infos from another publisher than the camera followed: not used.
    pub foreign_inputs: u64,
}

/// Runs until `shutdown` completes.
pub async fn run(
    bus: &Bus,
    params: DetectorParams,
    shutdown: impl Future<Output = ()>,
) -> Result<DetectStats, BusError> {
    let frames = bus.frame_subscriber().await?;
    let infos = bus.subscriber(topics::CAMERA_FRONT_INFO).await?;
    let out = bus.publisher(topics::PERCEPTION_OBJECTS).await?;
    let mut stats = DetectStats::default();
    let mut camera: Option<(CameraInfo, Detector)> = None;
    let mut tracker = Tracker::new();
    let mut waiting_logged = false;
    // One camera: frames and info from the publisher that named itself first.
    let mut frames_from = Following::new("camera/front");
    let mut info_from = Following::new("camera/front/info");
    tokio::pin!(shutdown);
    loop {
        let sample = tokio::select! {
            _ = &mut shutdown => break,
            s = frames.recv() => s,
        };
        if !frames_from.accept(sample.source().as_deref(), Instant::now()) {
            continue;
        }
        while let Some(info) = infos.try_recv() {
            if !info_from.accept(info.source.as_deref(), Instant::now()) {
                continue;
            }
            if camera.as_ref().is_none_or(|(known, _)| *known != info.msg) {
                tracing::info!(width = info.msg.width, height = info.msg.height, "camera info");
                camera = Some((info.msg.clone(), Detector::new(&info.msg, params)));
                tracker = Tracker::new();
            }
        }
        if camera.is_none() {
            if !waiting_logged {
                tracing::info!("waiting for camera/front/info before using frames");
                waiting_logged = true;
            }
            // The info is latched: it comes soon after start. The frame in hand is used then
            // (a lockstep controller waits for its detections).
            match infos.recv_timeout(Duration::from_millis(500)).await {
                Some(info) if info_from.accept(info.source.as_deref(), Instant::now()) => {
                    camera = Some((info.msg.clone(), Detector::new(&info.msg, params)))
                }
                _ => continue,
            }
        }
        let (info, detector) = camera.as_mut().expect("camera info is known here");
        let frame = sample.frame();
        let header = frame.header;
        if (frame.msg.width, frame.msg.height) != (info.width, info.height) {
            stats.unusable += 1;
            tracing::warn!(frame = ?(frame.msg.width, frame.msg.height), info = ?(info.width, info.height), "frame size unlike camera info: skipped");
            continue;
        }
        let rgb = match frame.msg.to_rgb8() {
            Ok(rgb) => rgb,
            Err(e) => {
                stats.unusable += 1;
                tracing::warn!("undecodable frame {}: {e}", header.seq);
                continue;
            }
        };
        let found = detector.detect(&rgb);
        let detections = tracker.update(&found, header.stamp_sim_ns as f64 / 1e9);
        stats.frames += 1;
        stats.detections += detections.len() as u64;
        out.put(
            header.stamp_sim_ns,
            &Detections { frame_seq: header.seq, frame_stamp_pub_ns: header.stamp_pub_ns, detections },
        )?;
    }
    stats.skipped = frames.stats().snapshot().skipped;
    stats.foreign_inputs = frames_from.rejected() + info_from.rejected();
    Ok(stats)
}
