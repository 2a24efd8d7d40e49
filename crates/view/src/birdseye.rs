//! The page's bird's-eye view: the road, the ego and the vehicles around it in the ego's frame
//! (x ahead, y to the left, metres), so the page draws without knowing the world's geometry.
//! The same vehicles and road as the Foxglove scene ([`super::scene`]), another projection.

use nalgebra::Vector2;
use serde::Serialize;

use super::scene::RoadLine;
use slipstream_contract::msg::{GroundTruthObjects, VehicleState};
use slipstream_model::vehicle::VehicleParams;

/// What a body is to the loop.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub(crate) enum Role {
    Ego,
    /// The true lead: the nearest vehicle ahead in the ego's lane.
    Lead,
    Other,
}

/// A vehicle's footprint.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub(crate) struct Footprint {
    /// The ground truth's id (none for the ego).
    pub id: Option<u32>,
    pub role: Role,
    /// The body's centre.
    pub x_m: f32,
    pub y_m: f32,
    pub yaw_rad: f32,
    pub length_m: f32,
    pub width_m: f32,
}

/// A line on the road.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub(crate) struct Line {
    pub edge: bool,
    pub points: Vec<[f32; 2]>,
}

#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub(crate) struct Birdseye {
    pub vehicles: Vec<Footprint>,
    pub road: Vec<Line>,
}

/// World -> the ego's frame (origin at its rear axle).
struct EgoFrame {
    origin: Vector2<f64>,
    cos: f64,
    sin: f64,
    yaw: f64,
}

impl EgoFrame {
    fn of(ego: &VehicleState) -> EgoFrame {
        let yaw = ego.yaw_in_world_rad;
        let p = ego.position_in_world_m;
        EgoFrame { origin: Vector2::new(p[0], p[1]), cos: yaw.cos(), sin: yaw.sin(), yaw }
    }

    fn point(&self, world: Vector2<f64>) -> [f32; 2] {
        let d = world - self.origin;
        [(d.x * self.cos + d.y * self.sin) as f32, (-d.x * self.sin + d.y * self.cos) as f32]
    }

    /// The footprint of a body whose rear axle is at `rear_axle` (world), heading `yaw`.
    fn footprint(
        &self,
        id: Option<u32>,
        role: Role,
        rear_axle: [f64; 3],
        yaw: f64,
        params: &VehicleParams,
    ) -> Footprint {
        let ahead = params.center_ahead_of_rear_axle_m();
        let center = Vector2::new(rear_axle[0] + ahead * yaw.cos(), rear_axle[1] + ahead * yaw.sin());
        let [x_m, y_m] = self.point(center);
        Footprint {
            id,
            role,
            x_m,
            y_m,
            yaw_rad: (yaw - self.yaw) as f32,
            length_m: params.size_m[0] as f32,
            width_m: params.size_m[1] as f32,
        }
    }
}

/// The scene around `ego`: its footprint first, then every vehicle the ground truth has, and
/// the road's lines when known.
pub(crate) fn birdseye(
    ego: &VehicleState,
    ego_params: &VehicleParams,
    truth: Option<&GroundTruthObjects>,
    road: Option<&[RoadLine]>,
) -> Birdseye {
    let frame = EgoFrame::of(ego);
    let lead = truth.and_then(|t| t.nearest_ahead_in_lane(ego.lane)).map(|l| l.id);
    let mut vehicles =
        vec![frame.footprint(None, Role::Ego, ego.position_in_world_m, ego.yaw_in_world_rad, ego_params)];
    for o in truth.iter().flat_map(|t| &t.objects) {
        let role = if lead == Some(o.id) { Role::Lead } else { Role::Other };
        let params = VehicleParams::of_class(o.class);
        vehicles.push(frame.footprint(Some(o.id), role, o.position_in_world_m, o.yaw_in_world_rad, &params));
    }
    let road = road
        .unwrap_or_default()
        .iter()
        .map(|l| Line { edge: l.edge, points: l.points.iter().map(|p| frame.point(*p)).collect() })
        .collect();
    Birdseye { vehicles, road }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_ego_frame_puts_ahead_on_x_and_left_on_y_whatever_the_heading() {
        let ego = VehicleState {
            position_in_world_m: [10.0, 5.0, 0.0],
            yaw_in_world_rad: std::f64::consts::FRAC_PI_2,
            ..slipstream_contract::msg::example_state()
        };
        let frame = EgoFrame::of(&ego);
        // Heading north: 20 m north of the ego is 20 m ahead; 3 m west is 3 m to its left.
        let [x, y] = frame.point(Vector2::new(10.0, 25.0));
        assert!((x - 20.0).abs() < 1e-4 && y.abs() < 1e-4, "{x} {y}");
        let [x, y] = frame.point(Vector2::new(7.0, 5.0));
        assert!(x.abs() < 1e-4 && (y - 3.0).abs() < 1e-4, "{x} {y}");
        let road = [RoadLine { edge: true, points: vec![Vector2::new(10.0, 105.0)] }];
        let b = birdseye(&ego, &VehicleParams::CAR, None, Some(&road));
        assert_eq!(b.vehicles.len(), 1);
        assert_eq!(b.vehicles[0].role, Role::Ego);
        let ahead = VehicleParams::CAR.center_ahead_of_rear_axle_m() as f32;
        assert!((b.vehicles[0].x_m - ahead).abs() < 1e-4 && b.vehicles[0].yaw_rad.abs() < 1e-6);
        assert!((b.road[0].points[0][0] - 100.0).abs() < 1e-3);
    }
}
