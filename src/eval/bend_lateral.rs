//! How well the detector places far vehicles across the road near bends: the lateral error of
//! matched detections 80-200 m ahead, by range band and by the tightest bend between the ego
//! and the vehicle, as bias and standard deviation. The ACC's in-lane test needs the lateral
//! uncertainty at a range and in a bend; this table is where that figure is measured
//! (`eval detect`, issue 39 part 5).

use nalgebra::Vector2;
use serde::Serialize;

use crate::msg::GroundTruthObject;
use crate::road::Road;

/// Range bands, metres ahead.
pub const RANGE_BANDS_M: [(f64, f64); 3] = [(80.0, 120.0), (120.0, 160.0), (160.0, 200.0)];
/// Bend bands by the tightest radius seen through, metres: straight (no curve between the ego
/// and the vehicle), then ever tighter.
pub const BEND_BANDS: [(&str, f64, f64); 4] = [
    ("straight", f64::INFINITY, f64::INFINITY),
    ("R >= 1000 m", 1000.0, f64::INFINITY),
    ("R 500-1000 m", 500.0, 1000.0),
    ("R < 500 m", 0.0, 500.0),
];

/// The tightest bend (|radius|) of `road` between road positions `from_s` and `to_s`; None on
/// a straight.
pub fn tightest_between(road: &Road, from_s: f64, to_s: f64) -> Option<f64> {
    let (lo, hi) = if from_s <= to_s { (from_s, to_s) } else { (to_s, from_s) };
    road.spec()
        .curves
        .iter()
        .filter(|c| c.start_m < hi && c.start_m + c.length_m > lo)
        .map(|c| c.radius_m.abs())
        .reduce(f64::min)
}

/// The ego's place along `road` (its world position `ego_xy`).
pub fn ego_s(road: &Road, ego_xy: [f64; 3]) -> f64 {
    road.project_anywhere(Vector2::new(ego_xy[0], ego_xy[1])).0
}

/// The bend a ground-truth vehicle is seen through from the ego at `ego_s` along the road.
pub fn bend_of(road: &Road, ego_s: f64, o: &GroundTruthObject) -> Option<f64> {
    let p = o.position_in_world_m;
    let (s, _) = road.project(Vector2::new(p[0], p[1]), ego_s + o.position_in_ego_m[0]);
    tightest_between(road, ego_s, s)
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
pub fn table(errors: impl Iterator<Item = (f64, Option<f64>, f64)> + Clone) -> Vec<LateralCell> {
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

/// The table as markdown: a row per range band, a column per bend band, "sigma (bias, n)".
pub fn markdown(cells: &[LateralCell]) -> String {
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
    s.push_str("\nLateral error of matched detections, metres: standard deviation (bias, count), by true distance and the tightest bend between the ego and the vehicle.\n");
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::msg::{Curve, RoadSpec};

    #[test]
    fn the_tightest_bend_between_two_places_is_found() {
        let road = Road::new(RoadSpec {
            curves: vec![
                Curve { start_m: 100.0, length_m: 100.0, radius_m: 800.0 },
                Curve { start_m: 300.0, length_m: 100.0, radius_m: -400.0 },
            ],
            ..RoadSpec::default()
        });
        assert_eq!(tightest_between(&road, 0.0, 90.0), None);
        assert_eq!(tightest_between(&road, 50.0, 150.0), Some(800.0));
        assert_eq!(tightest_between(&road, 350.0, 150.0), Some(400.0));
    }

    #[test]
    fn each_cell_holds_its_own_errors() {
        let errors =
            vec![(100.0, None, 0.1), (100.0, None, 0.3), (130.0, Some(450.0), -0.5), (130.0, Some(450.0), -0.7)];
        let cells = table(errors.into_iter());
        let straight = &cells[0];
        assert_eq!((straight.count, straight.bias_m.map(|b| (b * 100.0).round())), (2, Some(20.0)));
        assert!((straight.sigma_m.unwrap() - 0.1414).abs() < 1e-3);
        let tight = cells.iter().find(|c| c.range == "120-160 m" && c.bend == "R < 500 m").unwrap();
        assert_eq!(tight.count, 2);
        assert!((tight.bias_m.unwrap() + 0.6).abs() < 1e-9);
        assert_eq!(cells.iter().map(|c| c.count).sum::<usize>(), 4, "no error counted twice");
        assert!(markdown(&cells).contains("0.14 (+0.20, 2)"));
    }
}
