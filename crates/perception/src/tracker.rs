//! Tracking: detections of successive frames joined into tracks with stable ids, and each
//! track's distance and relative speed filtered by a constant-velocity Kalman filter.

use nalgebra::{Matrix2, Vector2};

use super::detector::FrameDetection;
use slipstream_contract::msg::{BoundingBox2d, Detection, ObjectClass};

/// The tracker's numbers: the `tracker` section of config/detect.json5, which says what each
/// means and holds the defaults.
#[derive(Debug, Clone, Copy, PartialEq, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TrackerParams {
    /// Acceleration noise of the constant-velocity model, m/s2 (a lead can brake hard).
    pub accel_noise_mps2: f64,
    /// A new track's relative speed: unknown, anything from a vehicle as fast as the ego to
    /// one standing (closing at motorway speed) or oncoming.
    pub new_track_speed_sigma_mps: f64,
    /// A track not seen for this long is dropped.
    pub max_coast_s: f64,
    /// Association: box overlap (IoU) above this, distance within gate_m + gate_share * d.
    pub min_overlap: f32,
    pub gate_m: f64,
    pub gate_share: f64,
    /// Seen this often, a track is confirmed; before, its confidence is scaled down.
    pub confirm_hits: u32,
    pub unconfirmed_confidence: f32,
    /// The share of the gap to a new lateral offset closed per frame.
    pub lateral_smoothing: f64,
}

impl Default for TrackerParams {
    fn default() -> Self {
        crate::settings::DetectSettings::default().tracker
    }
}

impl TrackerParams {
    /// The rules config/detect.json5 states for its `tracker` section (`prefix`).
    pub fn check(&self, prefix: &str) -> Result<(), slipstream_contract::config::Invalid> {
        use crate::settings::{positive, share};
        let key = |k: &str| format!("{prefix}.{k}");
        positive(&key("accel_noise_mps2"), self.accel_noise_mps2)?;
        positive(&key("new_track_speed_sigma_mps"), self.new_track_speed_sigma_mps)?;
        positive(&key("max_coast_s"), self.max_coast_s)?;
        positive(&key("gate_m"), self.gate_m)?;
        positive(&key("gate_share"), self.gate_share)?;
        if !(0.0..1.0).contains(&self.min_overlap) {
            let problem = format!("{}", self.min_overlap);
            return slipstream_contract::config::Invalid::err(key("min_overlap"), problem, "give a share in [0, 1)");
        }
        if self.confirm_hits == 0 {
            return slipstream_contract::config::Invalid::err(key("confirm_hits"), "0", "give a count >= 1");
        }
        share(&key("unconfirmed_confidence"), f64::from(self.unconfirmed_confidence), true)?;
        share(&key("lateral_smoothing"), self.lateral_smoothing, true)
    }
}

/// One tracked vehicle.
#[derive(Debug, Clone)]
pub(crate) struct Track {
    pub id: u32,
    /// Distance (m) and its rate (relative speed, m/s).
    x: Vector2<f64>,
    p: Matrix2<f64>,
    lateral_m: f64,
    pub bbox: BoundingBox2d,
    pub class: ObjectClass,
    pub hits: u32,
    last_seen_s: f64,
}

impl Track {
    pub(crate) fn distance_m(&self) -> f64 {
        self.x[0]
    }

    pub(crate) fn relative_speed_mps(&self) -> f64 {
        self.x[1]
    }

    /// The standard deviations of the distance and of the relative speed.
    pub(crate) fn sigmas(&self) -> (f64, f64) {
        (self.p[(0, 0)].max(0.0).sqrt(), self.p[(1, 1)].max(0.0).sqrt())
    }

    fn predict(&mut self, dt: f64, accel_noise_mps2: f64) {
        let f = Matrix2::new(1.0, dt, 0.0, 1.0);
        let q = accel_noise_mps2 * accel_noise_mps2;
        let noise = Matrix2::new(dt.powi(4) / 4.0, dt.powi(3) / 2.0, dt.powi(3) / 2.0, dt * dt) * q;
        self.x = f * self.x;
        self.p = f * self.p * f.transpose() + noise;
    }

    fn update(&mut self, d: &FrameDetection, t_s: f64, lateral_smoothing: f64) {
        // Measurement noise: the detector's, from the ground a row covers at that distance
        // through the camera that measured it.
        let r = d.distance_sigma_m * d.distance_sigma_m;
        let innovation = d.distance_m - self.x[0];
        let s = self.p[(0, 0)] + r;
        let k = Vector2::new(self.p[(0, 0)], self.p[(1, 0)]) / s;
        self.x += k * innovation;
        let i_kh = Matrix2::new(1.0 - k[0], 0.0, -k[1], 1.0);
        self.p = i_kh * self.p;
        self.lateral_m += lateral_smoothing * (d.lateral_offset_m - self.lateral_m);
        self.bbox = d.bbox;
        self.class = d.class;
        self.hits += 1;
        self.last_seen_s = t_s;
    }
}

/// Keeps the tracks of one camera.
#[derive(Debug)]
pub(crate) struct Tracker {
    params: TrackerParams,
    tracks: Vec<Track>,
    next_id: u32,
    last_t_s: Option<f64>,
}

impl Tracker {
    pub(crate) fn new(params: TrackerParams) -> Self {
        Tracker { params, tracks: Vec::new(), next_id: 1, last_t_s: None }
    }

    #[cfg(test)]
    fn tracks(&self) -> &[Track] {
        &self.tracks
    }

    /// Takes one frame's detections at simulation time `t_s`; returns them as tracked
    /// detections (same order as the input).
    pub(crate) fn update(&mut self, detections: &[FrameDetection], t_s: f64) -> Vec<Detection> {
        let dt = self.last_t_s.map_or(0.0, |last| (t_s - last).max(0.0));
        self.last_t_s = Some(t_s);
        let p = self.params;
        for t in &mut self.tracks {
            t.predict(dt, p.accel_noise_mps2);
        }
        // Greedy association, best box overlap first, gated on distance.
        let mut pairs: Vec<(f32, usize, usize)> = Vec::new();
        for (i, d) in detections.iter().enumerate() {
            for (j, t) in self.tracks.iter().enumerate() {
                let overlap = d.bbox.iou(&t.bbox);
                let gate = (d.distance_m - t.distance_m()).abs() < p.gate_m + p.gate_share * d.distance_m;
                if overlap > p.min_overlap && gate {
                    pairs.push((overlap, i, j));
                }
            }
        }
        pairs.sort_by(|a, b| b.0.total_cmp(&a.0));
        let mut track_of = vec![None; detections.len()];
        let mut taken = vec![false; self.tracks.len()];
        for (_, i, j) in pairs {
            if track_of[i].is_none() && !taken[j] {
                track_of[i] = Some(j);
                taken[j] = true;
            }
        }
        let mut out = Vec::with_capacity(detections.len());
        for (i, d) in detections.iter().enumerate() {
            let j = match track_of[i] {
                Some(j) => {
                    self.tracks[j].update(d, t_s, p.lateral_smoothing);
                    j
                }
                None => {
                    self.tracks.push(Track {
                        id: self.next_id,
                        x: Vector2::new(d.distance_m, 0.0),
                        p: Matrix2::new(d.distance_sigma_m.powi(2), 0.0, 0.0, p.new_track_speed_sigma_mps.powi(2)),
                        lateral_m: d.lateral_offset_m,
                        bbox: d.bbox,
                        class: d.class,
                        hits: 1,
                        last_seen_s: t_s,
                    });
                    self.next_id += 1;
                    self.tracks.len() - 1
                }
            };
            let t = &self.tracks[j];
            // A new track's speed is unknown (its sigma says how much): its confidence is
            // lowered until seen again.
            let settle = if t.hits >= p.confirm_hits { 1.0 } else { p.unconfirmed_confidence };
            let (distance_sigma_m, relative_speed_sigma_mps) = t.sigmas();
            out.push(Detection {
                track_id: t.id,
                class: t.class,
                bbox: d.bbox,
                confidence: (d.confidence * settle).clamp(0.0, 1.0),
                distance_m: t.distance_m(),
                lateral_offset_m: t.lateral_m,
                relative_speed_mps: t.relative_speed_mps(),
                distance_sigma_m,
                relative_speed_sigma_mps,
                brake_lights: d.brake_lights,
            });
        }
        self.tracks.retain(|t| t_s - t.last_seen_s <= p.max_coast_s);
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn det(distance_m: f64, u0: f32) -> FrameDetection {
        FrameDetection {
            bbox: BoundingBox2d { u_min_px: u0, v_min_px: 200.0, u_max_px: u0 + 40.0, v_max_px: 240.0 },
            class: ObjectClass::Car,
            distance_m,
            distance_sigma_m: 0.05 + 0.004 * distance_m,
            lateral_offset_m: 0.0,
            height_m: 1.4,
            width_m: 1.8,
            confidence: 0.9,
            brake_lights: false,
        }
    }

    #[test]
    fn a_closing_vehicle_keeps_its_id_and_its_relative_speed_converges() {
        let mut tracker = Tracker::new(TrackerParams::default());
        let mut last = Vec::new();
        for k in 0..40 {
            let t = k as f64 * 0.05;
            // Closing at 4 m/s from 40 m, with +-1% measurement noise.
            let noise = if k % 2 == 0 { 0.4 } else { -0.4 };
            last = tracker.update(&[det(40.0 - 4.0 * t + noise, 300.0)], t);
        }
        assert_eq!(last[0].track_id, 1);
        assert!((last[0].relative_speed_mps + 4.0).abs() < 0.6, "{:?}", last[0]);
        assert!((last[0].distance_m - (40.0 - 4.0 * 1.95)).abs() < 0.5, "{:?}", last[0]);
    }

    #[test]
    fn a_new_tracks_speed_is_reported_unknown_until_frames_have_measured_it() {
        // A car standing 150 m ahead of the ego at 30 m/s: ranges 1.5 m apart from frame to
        // frame, each good to the detector's sigma.
        let mut tracker = Tracker::new(TrackerParams::default());
        let mut sigmas = Vec::new();
        let mut last = Vec::new();
        for k in 0..20 {
            let t = k as f64 * 0.05;
            let noise = if k % 2 == 0 { 0.3 } else { -0.3 };
            last = tracker.update(&[det(150.0 - 30.0 * t + noise, 300.0)], t);
            sigmas.push(last[0].relative_speed_sigma_mps);
        }
        assert_eq!(sigmas[0], TrackerParams::default().new_track_speed_sigma_mps, "nothing measured yet");
        assert!(sigmas[1] > 10.0, "two ranges 1.5 m apart with 0.65 m noise: {:.1}", sigmas[1]);
        assert!(sigmas.windows(2).take(8).all(|w| w[1] < w[0]), "shrinks as frames come: {sigmas:.1?}");
        assert!(sigmas[19] < 3.0 && (last[0].relative_speed_mps + 30.0).abs() < 3.0, "{:?}", last[0]);
        assert!(
            last[0].distance_sigma_m > 0.0 && last[0].distance_sigma_m < 0.65,
            "better than one range: {:?}",
            last[0]
        );
    }

    #[test]
    fn separate_vehicles_get_separate_ids_and_lost_tracks_expire() {
        let mut tracker = Tracker::new(TrackerParams::default());
        let a = tracker.update(&[det(20.0, 100.0), det(35.0, 400.0)], 0.0);
        assert_eq!((a[0].track_id, a[1].track_id), (1, 2));
        let b = tracker.update(&[det(35.0, 401.0)], 0.05);
        assert_eq!(b[0].track_id, 2);
        tracker.update(&[], 1.0);
        assert!(tracker.tracks().is_empty());
        let c = tracker.update(&[det(20.0, 100.0)], 1.05);
        assert_eq!(c[0].track_id, 3, "a new track after the old one expired");
    }
}
