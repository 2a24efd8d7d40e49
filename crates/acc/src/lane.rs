//! The lane ahead on the road's map: where a point in the ego's frame lies across the ego's
//! lane, measured where the point is (a bend ahead bends the lane with it).

use nalgebra::Vector2;

use super::ego::{EgoNow, Pose};
use slipstream_model::road::Road;

/// The ego's lane on the map now: where a point in the ego's frame lies across that lane.
pub(super) struct LaneAhead<'a> {
    pub(super) road: &'a Road,
    pub(super) pose: Pose,
    pub(super) s_m: f64,
    pub(super) centre_d_m: f64,
}

impl LaneAhead<'_> {
    /// The ego's lane on `road`, when the pose is known and on the road; `last_s_m` (the ego's
    /// last place along it, a search hint) moves on.
    pub(super) fn find<'a>(road: Option<&'a Road>, last_s_m: &mut Option<f64>, ego: &EgoNow) -> Option<LaneAhead<'a>> {
        let (road, pose) = (road?, ego.pose?);
        let p = Vector2::new(pose.x_m, pose.y_m);
        let (s, d) = match *last_s_m {
            Some(hint) => road.project(p, hint),
            None => road.project_anywhere(p),
        };
        *last_s_m = Some(s);
        let lane = u32::try_from(road.lane_at(d)).ok()?;
        Some(LaneAhead { road, pose, s_m: s, centre_d_m: road.lane_center_d(lane) })
    }

    /// How far left of the ego lane's centre a point (ego frame: `x` forward, `y` left) is,
    /// measured across the road where the point is: a bend ahead bends the lane with it.
    pub(super) fn offset_m(&self, x_m: f64, y_m: f64) -> f64 {
        let (sin, cos) = self.pose.yaw_rad.sin_cos();
        let p = Vector2::new(self.pose.x_m + x_m * cos - y_m * sin, self.pose.y_m + x_m * sin + y_m * cos);
        let (_, d) = self.road.project(p, self.s_m + x_m);
        d - self.centre_d_m
    }
}
