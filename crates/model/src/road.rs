//! The road: a centre line (straight, with optional constant-radius curves) and parallel lanes.
//!
//! Positions on the road are given in road coordinates (s, d): s is the distance along the
//! centre line from the road start, d the signed lateral offset from it (positive left). The
//! road starts at the world origin heading along world +x. Lane 0 is the rightmost; lane i's
//! centre is at d = (i + 0.5 - lanes / 2) * lane_width.
//!
//! Shared by the domain modules like the vehicle model: the simulator builds its world on it,
//! the ACC finds its lane ahead on it (from the map the simulator publishes on sim/road).

use nalgebra::Vector2;

pub use slipstream_contract::msg::{Curve, LaneEnd, RoadSpec};

/// Spacing of the precomputed centre-line samples.
const SAMPLE_M: f64 = 0.5;

/// The centre line, sampled, with conversions between road and world coordinates.
#[derive(Debug, Clone)]
pub struct Road {
    spec: RoadSpec,
    points: Vec<Vector2<f64>>,
    headings: Vec<f64>,
}

impl Road {
    /// Integrates the curvature profile into centre-line samples. The spec must be valid
    /// (see the scenario checks): positive lanes, width and length.
    pub fn new(spec: RoadSpec) -> Road {
        let n = (spec.length_m / SAMPLE_M).ceil() as usize + 1;
        let mut points = Vec::with_capacity(n);
        let mut headings = Vec::with_capacity(n);
        let (mut p, mut heading) = (Vector2::zeros(), 0.0f64);
        for i in 0..n {
            points.push(p);
            headings.push(heading);
            // The heading change over the sample is exact; the chord follows the mean heading.
            let s = i as f64 * SAMPLE_M;
            let dh = turn_between(&spec.curves, s, s + SAMPLE_M);
            let mid = heading + dh / 2.0;
            p += Vector2::new(mid.cos(), mid.sin()) * SAMPLE_M;
            heading += dh;
        }
        Road { spec, points, headings }
    }

    pub fn spec(&self) -> &RoadSpec {
        &self.spec
    }

    pub fn lanes(&self) -> u32 {
        self.spec.lanes
    }

    pub fn lane_width_m(&self) -> f64 {
        self.spec.lane_width_m
    }

    /// The tightest bend (|radius|, m) between road positions `from_s` and `to_s`, in either
    /// order; None on a straight.
    pub fn tightest_radius_between(&self, from_s: f64, to_s: f64) -> Option<f64> {
        let (lo, hi) = if from_s <= to_s { (from_s, to_s) } else { (to_s, from_s) };
        self.spec
            .curves
            .iter()
            .filter(|c| c.start_m < hi && c.start_m + c.length_m > lo)
            .map(|c| c.radius_m.abs())
            .reduce(f64::min)
    }

    pub fn half_width_m(&self) -> f64 {
        self.spec.lanes as f64 * self.spec.lane_width_m / 2.0
    }

    /// Lateral offset of a lane's centre.
    pub fn lane_center_d(&self, lane: u32) -> f64 {
        (lane as f64 + 0.5 - self.spec.lanes as f64 / 2.0) * self.spec.lane_width_m
    }

    /// The lane that contains lateral offset `d`, or -1 off the road.
    pub fn lane_at(&self, d: f64) -> i32 {
        let from_right = d + self.half_width_m();
        if from_right < 0.0 || d > self.half_width_m() {
            return -1;
        }
        ((from_right / self.spec.lane_width_m) as i32).min(self.spec.lanes as i32 - 1)
    }

    /// Where `lane` ends, if it does.
    pub fn lane_end(&self, lane: u32) -> Option<&LaneEnd> {
        self.spec.lane_end(lane)
    }

    /// The share of `lane`'s width open at `s`: 1 before its taper, falling to 0 at its end.
    pub fn lane_open(&self, lane: u32, s: f64) -> f64 {
        self.lane_end(lane).map_or(1.0, |e| ((e.end_m - s) / e.taper_m).clamp(0.0, 1.0))
    }

    /// The road's right and left edges at `s` (lateral offsets): an outer lane that ends
    /// moves its edge in over the taper.
    pub fn edges_d(&self, s: f64) -> (f64, f64) {
        let (hw, w, last) = (self.half_width_m(), self.spec.lane_width_m, self.spec.lanes.saturating_sub(1));
        (-hw + (1.0 - self.lane_open(0, s)) * w, hw - (1.0 - self.lane_open(last, s)) * w)
    }

    /// Centre-line point and heading at `s`; beyond the ends the line goes on straight.
    pub fn center(&self, s: f64) -> (Vector2<f64>, f64) {
        let last = self.points.len() - 1;
        let f = s / SAMPLE_M;
        if f <= 0.0 {
            let h = self.headings[0];
            return (self.points[0] + Vector2::new(h.cos(), h.sin()) * s, h);
        }
        if f >= last as f64 {
            let h = self.headings[last];
            let beyond = s - last as f64 * SAMPLE_M;
            return (self.points[last] + Vector2::new(h.cos(), h.sin()) * beyond, h);
        }
        let i = f as usize;
        let t = f - i as f64;
        (self.points[i].lerp(&self.points[i + 1], t), self.headings[i] + (self.headings[i + 1] - self.headings[i]) * t)
    }

    /// World position of road coordinates (s, d).
    pub fn to_world(&self, s: f64, d: f64) -> Vector2<f64> {
        let (p, h) = self.center(s);
        p + Vector2::new(-h.sin(), h.cos()) * d
    }

    /// Road coordinates (s, d) of a world point, searching near `hint_s` (the point's last
    /// known s; vehicles move a fraction of a metre per step).
    pub fn project(&self, p: Vector2<f64>, hint_s: f64) -> (f64, f64) {
        let last = self.points.len() - 1;
        let window = (40.0 / SAMPLE_M) as usize;
        let centre = (hint_s / SAMPLE_M).round().clamp(0.0, last as f64) as usize;
        let (lo, hi) = (centre.saturating_sub(window), (centre + window).min(last));
        let best = (lo..=hi)
            .min_by(|&a, &b| (self.points[a] - p).norm_squared().total_cmp(&(self.points[b] - p).norm_squared()))
            .unwrap_or(0);
        let h = self.headings[best];
        let rel = p - self.points[best];
        let along = rel.x * h.cos() + rel.y * h.sin();
        let across = -rel.x * h.sin() + rel.y * h.cos();
        (best as f64 * SAMPLE_M + along, across)
    }

    /// Road coordinates of a world point with no hint: a scan of the whole road.
    pub fn project_anywhere(&self, p: Vector2<f64>) -> (f64, f64) {
        let best = (0..self.points.len())
            .min_by(|&a, &b| (self.points[a] - p).norm_squared().total_cmp(&(self.points[b] - p).norm_squared()))
            .unwrap_or(0);
        self.project(p, best as f64 * SAMPLE_M)
    }
}

/// Heading change (rad, positive left) of the centre line between `s0` and `s1`.
fn turn_between(curves: &[Curve], s0: f64, s1: f64) -> f64 {
    curves
        .iter()
        .map(|c| {
            let overlap = s1.min(c.start_m + c.length_m) - s0.max(c.start_m);
            overlap.max(0.0) / c.radius_m
        })
        .sum()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn straight_road_is_the_x_axis_and_lanes_count_from_the_right() {
        let road = Road::new(RoadSpec::default());
        assert_eq!(road.to_world(100.0, 1.0), Vector2::new(100.0, 1.0));
        assert_eq!(road.lane_center_d(0), -3.5);
        assert_eq!(road.lane_center_d(1), 0.0);
        assert_eq!(road.lane_at(-3.5), 0);
        assert_eq!(road.lane_at(0.2), 1);
        assert_eq!(road.lane_at(5.0), 2);
        assert_eq!(road.lane_at(5.5), -1);
        assert_eq!(road.lane_at(-5.5), -1);
    }

    #[test]
    fn a_quarter_circle_turns_ninety_degrees_and_projection_inverts_to_world() {
        let r = 200.0;
        let quarter = std::f64::consts::FRAC_PI_2 * r;
        let spec =
            RoadSpec { curves: vec![Curve { start_m: 100.0, length_m: quarter, radius_m: r }], ..Default::default() };
        let road = Road::new(spec);
        let (end, heading) = road.center(100.0 + quarter);
        assert!((heading - std::f64::consts::FRAC_PI_2).abs() < 1e-3, "heading {heading}");
        let (_, after) = road.center(100.0 + quarter + 2.0);
        assert!((after - std::f64::consts::FRAC_PI_2).abs() < 1e-9, "heading after the curve {after}");
        assert!((end - Vector2::new(100.0 + r, r)).norm() < 0.05, "arc end {end}");
        for &(s, d) in &[(50.0, 1.2), (150.0, -3.0), (300.0, 4.0), (600.0, 0.0)] {
            let p = road.to_world(s, d);
            let (s2, d2) = road.project(p, s + 3.0);
            assert!((s2 - s).abs() < 0.02 && (d2 - d).abs() < 0.02, "({s},{d}) -> ({s2},{d2})");
            let (s3, d3) = road.project_anywhere(p);
            assert!((s3 - s).abs() < 0.02 && (d3 - d).abs() < 0.02);
        }
    }
}
