//! sim/road: the road the vehicles drive on, as the simulator announces it (latched): what a
//! controller needs to know where its lane goes ahead. The same description is a scenario's
//! `road` block (docs/simulator.md).

use serde::{Deserialize, Serialize};

use super::{Message, MessageKind, Unsound};
use crate::config::Invalid;

/// A constant-radius curve on the centre line.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Curve {
    /// Where the curve starts, along the centre line.
    pub start_m: f64,
    pub length_m: f64,
    /// Radius of the centre line; positive turns left, negative right.
    pub radius_m: f64,
}

/// An outer lane that ends: full width until `end_m - taper_m`, narrowing to nothing at
/// `end_m` (its outer edge moving in), gone beyond. Traffic in it merges before the end.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LaneEnd {
    /// 0 (the rightmost) or the leftmost lane.
    pub lane: u32,
    pub end_m: f64,
    #[serde(default = "LaneEnd::default_taper_m")]
    pub taper_m: f64,
}

impl LaneEnd {
    fn default_taper_m() -> f64 {
        120.0
    }
}

/// The road as a scenario describes it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RoadSpec {
    pub lanes: u32,
    pub lane_width_m: f64,
    pub length_m: f64,
    pub curves: Vec<Curve>,
    /// Outer lanes that end (at most one end per lane).
    pub lane_ends: Vec<LaneEnd>,
}

impl Default for RoadSpec {
    fn default() -> Self {
        RoadSpec { lanes: 3, lane_width_m: 3.5, length_m: 4000.0, curves: Vec::new(), lane_ends: Vec::new() }
    }
}

impl RoadSpec {
    /// Where `lane` ends, if it does.
    pub fn lane_end(&self, lane: u32) -> Option<&LaneEnd> {
        self.lane_ends.iter().find(|e| e.lane == lane)
    }

    /// The limits a scenario's road must keep (docs/simulator.md): the first one off.
    pub fn invalid(&self) -> Option<Invalid> {
        let bad = |key: &str, problem: String, fix: &str| Some(Invalid::new(key, problem, fix));
        if !(1..=8).contains(&self.lanes) {
            return bad("road.lanes", format!("{} lanes", self.lanes), "use 1 to 8 lanes");
        }
        if !(2.0..=6.0).contains(&self.lane_width_m) {
            return bad("road.lane_width_m", format!("{} m", self.lane_width_m), "use 2 to 6 m");
        }
        if !(self.length_m >= 100.0 && self.length_m <= 100_000.0) {
            return bad("road.length_m", format!("{} m", self.length_m), "use 100 m to 100 km");
        }
        for (i, c) in self.curves.iter().enumerate() {
            if !(c.radius_m.abs() >= 30.0 && c.radius_m.is_finite()) {
                return bad(
                    &format!("road.curves[{i}].radius_m"),
                    format!("radius {} m is too tight", c.radius_m),
                    "use |radius| >= 30 m (positive turns left, negative right)",
                );
            }
            if !(c.length_m > 0.0 && c.start_m >= 0.0 && c.length_m.is_finite() && c.start_m.is_finite()) {
                return bad(
                    &format!("road.curves[{i}]"),
                    "start_m must be >= 0 and length_m > 0".into(),
                    "see docs/simulator.md (scenario format)",
                );
            }
        }
        for (i, e) in self.lane_ends.iter().enumerate() {
            let key = |k: &str| format!("road.lane_ends[{i}]{k}");
            if self.lanes < 2 || (e.lane != 0 && e.lane != self.lanes - 1) {
                return bad(
                    &key(".lane"),
                    format!("lane {} is not an outer lane of a {}-lane road", e.lane, self.lanes),
                    "end lane 0 (rightmost) or the leftmost lane, on a road of 2 lanes or more",
                );
            }
            if !(e.taper_m >= 20.0 && e.taper_m.is_finite() && e.end_m >= e.taper_m && e.end_m <= self.length_m) {
                return bad(
                    &key(""),
                    format!("end_m {} and taper_m {}", e.end_m, e.taper_m),
                    "use taper_m >= 20 m and taper_m <= end_m <= road.length_m",
                );
            }
            if self.lane_ends[..i].iter().any(|o| o.lane == e.lane) {
                return bad(&key(".lane"), format!("lane {} ends twice", e.lane), "give each lane one end");
            }
        }
        None
    }
}

impl Message for RoadSpec {
    const KIND: MessageKind = MessageKind::RoadMap;

    fn check(&self) -> Result<(), Unsound> {
        self.invalid().map_or(Ok(()), |i| Err(Unsound(format!("{}: {}", i.key, i.problem))))
    }
}
