//! How well the detector places far vehicles across the road near bends: the lateral error of
//! matched detections 40-200 m ahead, and the error of their place across the road (where the
//! detected point falls on the road's map, against the vehicle's own), by range band and by
//! the tightest bend between the ego and the vehicle, as bias and standard deviation. The
//! ACC's in-lane probability needs the uncertainty of a vehicle's place across its lane at a
//! range and in a bend; this table is where that figure is measured (`eval detect`).
//! In a bend the place across the road takes the range's error too: the line of
//! sight crosses the lanes there.

use nalgebra::Vector2;
use serde::Serialize;

use slipstream_acc::in_lane::{BEND_MIN_RADIUS_M, GENTLE_MIN_RADIUS_M};
use slipstream_contract::msg::GroundTruthObject;
use slipstream_model::road::Road;

/// Range bands, metres ahead.
pub(crate) const RANGE_BANDS_M: [(f64, f64); 4] = [(40.0, 80.0), (80.0, 120.0), (120.0, 160.0), (160.0, 200.0)];
/// Bend bands by the tightest radius seen through, metres: straight (no curve between the ego
/// and the vehicle), then ever tighter: the ACC's table's classes (crates/acc/src/in_lane.rs).
pub(crate) const BEND_BANDS: [(&str, f64, f64); 4] = [
    ("straight", f64::INFINITY, f64::INFINITY),
    ("R >= 1000 m", GENTLE_MIN_RADIUS_M, f64::INFINITY),
    ("R 500-1000 m", BEND_MIN_RADIUS_M, GENTLE_MIN_RADIUS_M),
    ("R < 500 m", 0.0, BEND_MIN_RADIUS_M),
];

/// The road as seen from the ego's pose: the bend each vehicle is seen through, and where a
/// point seen from the ego lies across the road.
pub(crate) struct RoadView<'a> {
    road: &'a Road,
    ego_s: f64,
    ego_xy: Vector2<f64>,
    yaw_rad: f64,
}

impl<'a> RoadView<'a> {
    /// From the ego's world position and heading.
    pub(crate) fn new(road: &'a Road, ego_xyz: [f64; 3], yaw_rad: f64) -> Self {
        let ego_xy = Vector2::new(ego_xyz[0], ego_xyz[1]);
        RoadView { road, ego_s: road.project_anywhere(ego_xy).0, ego_xy, yaw_rad }
    }

    /// The bend a ground-truth vehicle is seen through.
    pub(crate) fn bend_of(&self, o: &GroundTruthObject) -> Option<f64> {
        let p = o.position_in_world_m;
        let (s, _) = self.road.project(Vector2::new(p[0], p[1]), self.ego_s + o.position_in_ego_m[0]);
        self.road.tightest_radius_between(self.ego_s, s)
    }

    /// Where a point `x_m` ahead and `y_m` left of the ego lies across the road (metres left of
    /// the reference line), measured where the point is.
    pub(crate) fn across_m(&self, x_m: f64, y_m: f64) -> f64 {
        let (sin, cos) = self.yaw_rad.sin_cos();
        let p = self.ego_xy + Vector2::new(x_m * cos - y_m * sin, x_m * sin + y_m * cos);
        self.road.project(p, self.ego_s + x_m).1
    }
}

/// One cell of the table: range band x bend band.
#[derive(Debug, Clone, Serialize)]
pub struct LateralCell {
    pub range: String,
    pub bend: String,
    /// Matched detections in the cell.
    pub count: usize,
    /// Mean signed error (detected - true, positive left), metres.
    pub bias_m: Option<f64>,
    /// Standard deviation of the signed error, metres.
    pub sigma_m: Option<f64>,
}

/// The table from (true distance, bend radius, signed lateral error) triples.
pub(crate) fn table(errors: impl Iterator<Item = (f64, Option<f64>, f64)> + Clone) -> Vec<LateralCell> {
    let mut cells = Vec::new();
    for &(lo, hi) in &RANGE_BANDS_M {
        for &(name, r_lo, r_hi) in &BEND_BANDS {
            let in_bend = |r: Option<f64>| match r {
                None => r_lo.is_infinite(),
                Some(r) => r_lo.is_finite() && r >= r_lo && r < r_hi,
            };
            let v: Vec<f64> =
                errors.clone().filter(|(x, r, _)| *x >= lo && *x < hi && in_bend(*r)).map(|(_, _, e)| e).collect();
            let n = v.len();
            let mean = (n > 0).then(|| v.iter().sum::<f64>() / n as f64);
            let sigma = mean
                .filter(|_| n > 1)
                .map(|m| (v.iter().map(|e| (e - m).powi(2)).sum::<f64>() / (n - 1) as f64).sqrt());
            cells.push(LateralCell {
                range: format!("{lo:.0}-{hi:.0} m"),
                bend: name.to_string(),
                count: n,
                bias_m: mean,
                sigma_m: sigma,
            });
        }
    }
    cells
}

/// The table as markdown: a row per range band, a column per bend band, "sigma (bias, n)",
/// then `caption`.
pub(crate) fn markdown(cells: &[LateralCell], caption: &str) -> String {
    let mut s = String::from("| range |");
    for (name, _, _) in BEND_BANDS {
        s.push_str(&format!(" {name} |"));
    }
    s.push_str("\n|---|");
    s.push_str(&"---|".repeat(BEND_BANDS.len()));
    s.push('\n');
    for row in cells.chunks(BEND_BANDS.len()) {
        s.push_str(&format!("| {} |", row[0].range));
        for c in row {
            match (c.sigma_m, c.bias_m) {
                (Some(sd), Some(b)) => s.push_str(&format!(" {sd:.2} ({b:+.2}, {}) |", c.count)),
                _ => s.push_str(&format!(" - ({}) |", c.count)),
            }
        }
        s.push('\n');
    }
    s.push('\n');
    s.push_str(caption);
    s.push('\n');
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use slipstream_contract::msg::{Curve, RoadSpec};

    #[test]
    fn the_tightest_bend_between_two_places_is_found() {
        let road = Road::new(RoadSpec {
            curves: vec![
                Curve { start_m: 100.0, length_m: 100.0, radius_m: 800.0 },
                Curve { start_m: 300.0, length_m: 100.0, radius_m: -400.0 },
            ],
            ..RoadSpec::default()
        });
        assert_eq!(road.tightest_radius_between(0.0, 90.0), None);
        assert_eq!(road.tightest_radius_between(50.0, 150.0), Some(800.0));
        assert_eq!(road.tightest_radius_between(350.0, 150.0), Some(400.0));
    }

    #[test]
    fn a_point_on_a_lane_ahead_is_placed_on_that_lane_even_round_a_bend() {
        let road = Road::new(RoadSpec {
            curves: vec![Curve { start_m: 50.0, length_m: 400.0, radius_m: 500.0 }],
            ..RoadSpec::default()
        });
        // The ego on the road's start, heading along it; a point 150 m along its own lane's
        // centre (into the left bend) and one a lane's width further left.
        let (ego_d, lane_m) = (road.lane_center_d(1), road.lane_width_m());
        let (start, heading) = (road.to_world(0.0, ego_d), road.center(0.0).1);
        let view = RoadView::new(&road, [start.x, start.y, 0.0], heading);
        let ahead = |d: f64| {
            let p = road.to_world(150.0, d);
            let (sin, cos) = heading.sin_cos();
            let rel = p - start;
            (rel.x * cos + rel.y * sin, -rel.x * sin + rel.y * cos)
        };
        let (x, y) = ahead(ego_d);
        assert!(y > 8.0, "the bend carries the lane {y:.1} m left of the straight-ahead line");
        assert!((view.across_m(x, y) - ego_d).abs() < 0.05, "{}", view.across_m(x, y));
        let (x, y) = ahead(ego_d + lane_m);
        assert!((view.across_m(x, y) - ego_d - lane_m).abs() < 0.05);
        // A range 5 m short along the line of sight falls across the lane, not along it.
        let short = view.across_m(x * (1.0 - 5.0 / x.hypot(y)), y * (1.0 - 5.0 / x.hypot(y)));
        assert!((short - ego_d - lane_m).abs() > 0.5, "{short}");
    }

    #[test]
    fn each_cell_holds_its_own_errors() {
        let errors =
            vec![(100.0, None, 0.1), (100.0, None, 0.3), (130.0, Some(450.0), -0.5), (130.0, Some(450.0), -0.7)];
        let cells = table(errors.into_iter());
        let straight = cells.iter().find(|c| c.range == "80-120 m" && c.bend == "straight").unwrap();
        assert_eq!((straight.count, straight.bias_m.map(|b| (b * 100.0).round())), (2, Some(20.0)));
        assert!((straight.sigma_m.unwrap() - 0.1414).abs() < 1e-3);
        let tight = cells.iter().find(|c| c.range == "120-160 m" && c.bend == "R < 500 m").unwrap();
        assert_eq!(tight.count, 2);
        assert!((tight.bias_m.unwrap() + 0.6).abs() < 1e-9);
        assert_eq!(cells.iter().map(|c| c.count).sum::<usize>(), 4, "no error counted twice");
        assert!(markdown(&cells, "caption").contains("0.14 (+0.20, 2)"));
    }
}
