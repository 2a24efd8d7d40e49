//! What the view's page shows, kept current as the loop's messages arrive: the last few camera
//! frames (by reference to their Zenoh payloads, never copied here), each front frame paired
//! with the boxes drawn on it, the ACC's series over the last minute, the bird's-eye scene.
//!
//! A page asks for a snapshot and then for the frame it names, so the boxes it draws are those
//! of the frame it shows, however late the page is: the snapshot names the newest frame whose
//! detections have arrived (the newest frame at all when no detector answers).

use std::collections::VecDeque;

use serde::Serialize;

use super::birdseye::Birdseye;
use super::scene::AccSeries;
use slipstream_contract::bus::FrameSample;
use slipstream_contract::msg::{Detections, GroundTruthObjects};

/// Frames kept per camera: enough for the detections of a frame to arrive after it.
pub(crate) const FRAMES_KEPT: usize = 8;
/// Simulated seconds of series a page can ask for.
pub(crate) const SERIES_KEPT_S: f64 = 60.0;

/// The cameras the page shows.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Camera {
    Front = 0,
    Narrow = 1,
}

impl Camera {
    pub(crate) fn parse(name: &str) -> Option<Camera> {
        match name {
            "front" => Some(Camera::Front),
            "narrow" => Some(Camera::Narrow),
            _ => None,
        }
    }
}

/// A frame kept: its number here (counts every frame received), stamp and geometry.
#[derive(Clone)]
pub(crate) struct Kept {
    pub seq: u64,
    pub stamp: u64,
    pub width: u32,
    pub height: u32,
    pub sample: FrameSample,
}

/// What a box on the image is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub(crate) enum BoxKind {
    /// A vehicle the camera sees, as the simulator knows it.
    Truth,
    /// A track the detector reported.
    Detection,
    /// The track the ACC follows.
    Lead,
}

/// A box in the front camera's pixels.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub(crate) struct ImageBox {
    pub kind: BoxKind,
    /// Ground-truth id or track id.
    pub id: u32,
    pub u0: f32,
    pub v0: f32,
    pub u1: f32,
    pub v1: f32,
    pub distance_m: Option<f64>,
}

/// A front frame and what is drawn on it.
struct Pairing {
    stamp: u64,
    truth: Vec<ImageBox>,
    detections: Option<Vec<ImageBox>>,
}

/// The frame a snapshot names, with its boxes. Stamps go to the page as strings: nanoseconds
/// since the epoch do not fit a JavaScript number exactly.
#[derive(Debug, Clone, Serialize)]
pub(crate) struct Shot {
    #[serde(serialize_with = "as_string")]
    pub stamp: u64,
    pub seq: u64,
    pub width: u32,
    pub height: u32,
    /// Whether the detector's boxes for this frame are in (false: ground truth only).
    pub detected: bool,
    pub boxes: Vec<ImageBox>,
}

/// The narrow camera's newest frame, when it has one.
#[derive(Debug, Clone, Serialize)]
pub(crate) struct Other {
    #[serde(serialize_with = "as_string")]
    pub stamp: u64,
    pub seq: u64,
    pub width: u32,
    pub height: u32,
}

/// What the page draws, from one lock of the board.
#[derive(Debug, Clone, Serialize)]
pub(crate) struct Snapshot {
    pub front: Option<Shot>,
    pub narrow: Option<Other>,
    /// The series after the time the page asked from.
    pub series: Vec<AccSeries>,
    pub scene: Option<Birdseye>,
    /// How the run ended, once the simulator said so (sim/events ScenarioEnd); none while it
    /// runs, and again when a scenario starts.
    pub ended: Option<String>,
}

#[derive(Default)]
pub(crate) struct Board {
    frames: [VecDeque<Kept>; 2],
    received: [u64; 2],
    pairs: VecDeque<Pairing>,
    truth: Vec<ImageBox>,
    lead_track: Option<u32>,
    series: VecDeque<AccSeries>,
    scene: Option<Birdseye>,
    ended: Option<String>,
}

impl Board {
    /// The simulator started a scenario (`None`) or ended one with `reason`.
    pub(crate) fn on_run(&mut self, ended: Option<String>) {
        self.ended = ended;
    }

    pub(crate) fn on_frame(&mut self, camera: Camera, sample: FrameSample) {
        let (stamp, width, height) = {
            let f = sample.frame();
            (f.header.stamp_pub_ns, f.msg.width, f.msg.height)
        };
        let i = camera as usize;
        self.received[i] += 1;
        push_bounded(&mut self.frames[i], Kept { seq: self.received[i], stamp, width, height, sample }, FRAMES_KEPT);
        if camera == Camera::Front {
            let pairing = Pairing { stamp, truth: self.truth.clone(), detections: None };
            push_bounded(&mut self.pairs, pairing, FRAMES_KEPT);
        }
    }

    pub(crate) fn on_truth(&mut self, truth: &GroundTruthObjects) {
        self.truth = truth
            .objects
            .iter()
            .filter_map(|o| o.image_box().map(|b| (o, b)))
            .map(|(o, b)| ImageBox {
                kind: BoxKind::Truth,
                id: o.id,
                u0: b.u_min_px,
                v0: b.v_min_px,
                u1: b.u_max_px,
                v1: b.v_max_px,
                distance_m: Some(o.position_in_ego_m[0]),
            })
            .collect();
    }

    pub(crate) fn on_detections(&mut self, d: &Detections) {
        let lead = self.lead_track;
        let boxes = d
            .detections
            .iter()
            .map(|t| ImageBox {
                kind: if lead == Some(t.track_id) { BoxKind::Lead } else { BoxKind::Detection },
                id: t.track_id,
                u0: t.bbox.u_min_px,
                v0: t.bbox.v_min_px,
                u1: t.bbox.u_max_px,
                v1: t.bbox.v_max_px,
                distance_m: Some(t.distance_m),
            })
            .collect();
        if let Some(p) = self.pairs.iter_mut().rev().find(|p| p.stamp == d.frame_stamp_pub_ns) {
            p.detections = Some(boxes);
        }
    }

    /// The track the ACC follows now (its status), marked on the detections that follow.
    pub(crate) fn on_lead(&mut self, track: Option<u32>) {
        self.lead_track = track;
    }

    /// A sample of the series; a sample earlier than the last starts a new run's.
    pub(crate) fn on_series(&mut self, sample: AccSeries) {
        if self.series.back().is_some_and(|last| sample.t_s < last.t_s) {
            self.series.clear();
        }
        let t = sample.t_s;
        self.series.push_back(sample);
        while self.series.front().is_some_and(|s| s.t_s < t - SERIES_KEPT_S) {
            self.series.pop_front();
        }
    }

    pub(crate) fn on_scene(&mut self, scene: Birdseye) {
        self.scene = Some(scene);
    }

    /// The frame of `camera` stamped `stamp`, or its newest when `stamp` is none.
    pub(crate) fn frame(&self, camera: Camera, stamp: Option<u64>) -> Option<Kept> {
        let kept = &self.frames[camera as usize];
        match stamp {
            Some(s) => kept.iter().rev().find(|k| k.stamp == s).cloned(),
            None => kept.back().cloned(),
        }
    }

    /// The page's next picture: the series after `since_s` (all kept when it is none or
    /// later than the newest, as after a restart).
    pub(crate) fn snapshot(&self, since_s: Option<f64>) -> Snapshot {
        let newest = self.series.back().map_or(f64::NEG_INFINITY, |s| s.t_s);
        let from = since_s.filter(|s| *s <= newest).unwrap_or(f64::NEG_INFINITY);
        Snapshot {
            front: self.shot(),
            narrow: self.frames[Camera::Narrow as usize].back().map(|k| Other {
                stamp: k.stamp,
                seq: k.seq,
                width: k.width,
                height: k.height,
            }),
            series: self.series.iter().filter(|s| s.t_s > from).cloned().collect(),
            scene: self.scene.clone(),
            ended: self.ended.clone(),
        }
    }

    /// The newest front frame with its detections in, else the newest.
    fn shot(&self) -> Option<Shot> {
        let kept = &self.frames[Camera::Front as usize];
        let complete =
            self.pairs.iter().rev().find(|p| p.detections.is_some() && kept.iter().any(|k| k.stamp == p.stamp));
        let pairing = complete.or(self.pairs.back())?;
        let frame = kept.iter().find(|k| k.stamp == pairing.stamp)?;
        let mut boxes = pairing.truth.clone();
        boxes.extend(pairing.detections.iter().flatten().cloned());
        Some(Shot {
            stamp: frame.stamp,
            seq: frame.seq,
            width: frame.width,
            height: frame.height,
            detected: pairing.detections.is_some(),
            boxes,
        })
    }
}

fn as_string<S: serde::Serializer>(v: &u64, s: S) -> Result<S::Ok, S::Error> {
    s.collect_str(v)
}

fn push_bounded<T>(q: &mut VecDeque<T>, item: T, cap: usize) {
    if q.len() == cap {
        q.pop_front();
    }
    q.push_back(item);
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(t_s: f64) -> AccSeries {
        AccSeries {
            t_s,
            speed_mps: t_s,
            accel_mps2: 0.0,
            set_speed_mps: None,
            time_gap_s: None,
            mode: None,
            gap_m: None,
            desired_gap_m: None,
            ttc_s: None,
            truth_gap_m: None,
            warnings: Vec::new(),
        }
    }

    #[test]
    fn the_series_keeps_a_minute_answers_after_a_time_and_restarts_with_a_new_run() {
        let mut b = Board::default();
        for k in 0..=1000 {
            b.on_series(sample(k as f64 * 0.1));
        }
        let all = b.snapshot(None).series;
        assert!((all[0].t_s - 40.0).abs() < 0.11 && (all.last().unwrap().t_s - 100.0).abs() < 1e-9);
        assert_eq!(b.snapshot(Some(99.75)).series.len(), 3);
        // A page that saw a later run (or a clock ahead) gets everything kept.
        assert_eq!(b.snapshot(Some(500.0)).series.len(), all.len());
        b.on_series(sample(0.0));
        assert_eq!(b.snapshot(None).series.len(), 1);
    }
}
