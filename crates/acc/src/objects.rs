//! What the controller is fed about the vehicles ahead: one frame of objects, from the
//! detector's detections or the simulator's ground truth, in the ego's frame.

use slipstream_contract::msg::{Detections, GroundTruthObjects};

/// A vehicle ahead, as perception (or ground truth) reports it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Object {
    pub id: u32,
    /// From the ego's origin (rear axle) to the object's rear, along ego x.
    pub distance_m: f64,
    /// Its expected error as perception reports it (0: exact, as ground truth).
    pub distance_sigma_m: f64,
    /// The object's centre, ego y (positive left).
    pub lateral_m: f64,
    /// Object speed minus ego speed along ego x (negative: closing in).
    pub relative_speed_mps: f64,
    /// Its expected error as perception reports it (0: exact, as ground truth).
    pub relative_speed_sigma_mps: f64,
    /// Its brake lights are on.
    pub brake_lights: bool,
}

/// The objects of one camera frame.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct PerceptionFrame {
    /// Simulation time of the frame.
    pub stamp_s: f64,
    pub objects: Vec<Object>,
}

impl PerceptionFrame {
    pub fn from_detections(stamp_s: f64, d: &Detections) -> Self {
        let objects = d
            .detections
            .iter()
            .map(|d| Object {
                id: d.track_id,
                distance_m: d.distance_m,
                distance_sigma_m: d.distance_sigma_m,
                lateral_m: d.lateral_offset_m,
                relative_speed_mps: d.relative_speed_mps,
                relative_speed_sigma_mps: d.relative_speed_sigma_mps,
                brake_lights: d.brake_lights,
            })
            .collect();
        PerceptionFrame { stamp_s, objects }
    }

    /// Ground truth as perception: every vehicle ahead of the ego's origin.
    pub fn from_ground_truth(stamp_s: f64, gt: &GroundTruthObjects) -> Self {
        let objects = gt
            .objects
            .iter()
            .filter(|o| o.position_in_ego_m[0] > 0.0)
            .map(|o| Object {
                id: o.id,
                distance_m: o.position_in_ego_m[0],
                distance_sigma_m: 0.0,
                lateral_m: o.position_in_ego_m[1],
                relative_speed_mps: o.velocity_in_ego_mps[0],
                relative_speed_sigma_mps: 0.0,
                brake_lights: o.brake_lights,
            })
            .collect();
        PerceptionFrame { stamp_s, objects }
    }
}
