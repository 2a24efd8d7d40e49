//! Other vehicles: ground truth from the simulator and detections from perception.

use serde::{Deserialize, Serialize};

use super::{Message, MessageKind, Unsound, Vec3};

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum ObjectClass {
    Unknown,
    Car,
    Van,
    Truck,
    /// A motorcycle with its rider (appended: older payloads decode unchanged).
    Motorcycle,
}

/// An axis-aligned box in image pixels (u right, v down), min inclusive, max exclusive.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct BoundingBox2d {
    pub u_min_px: f32,
    pub v_min_px: f32,
    pub u_max_px: f32,
    pub v_max_px: f32,
}

impl BoundingBox2d {
    /// Intersection over union with `other`: 0 (apart) to 1 (the same box).
    pub fn iou(&self, other: &BoundingBox2d) -> f32 {
        let iw = (self.u_max_px.min(other.u_max_px) - self.u_min_px.max(other.u_min_px)).max(0.0);
        let ih = (self.v_max_px.min(other.v_max_px) - self.v_min_px.max(other.v_min_px)).max(0.0);
        let inter = iw * ih;
        let area = |r: &BoundingBox2d| (r.u_max_px - r.u_min_px) * (r.v_max_px - r.v_min_px);
        let union = area(self) + area(other) - inter;
        if union <= 0.0 {
            0.0
        } else {
            inter / union
        }
    }
}

/// One other vehicle as the simulator knows it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GroundTruthObject {
    pub id: u32,
    pub class: ObjectClass,
    /// Length, width, height.
    pub size_m: Vec3,
    /// Lane index (0 = rightmost), -1 off the road.
    pub lane: i32,
    pub position_in_world_m: Vec3,
    pub yaw_in_world_rad: f64,
    pub velocity_in_world_mps: Vec3,
    /// Centre of the object's rear face in the ego body frame.
    pub position_in_ego_m: Vec3,
    pub yaw_in_ego_rad: f64,
    /// Velocity relative to the ego, in the ego body frame: the rate of change of
    /// `position_in_ego_m` (the frame turns with the ego, as a sensor's range rate sees it).
    pub velocity_in_ego_mps: Vec3,
    /// Box in the camera image, None when outside the image.
    pub bbox: Option<BoundingBox2d>,
    /// Fraction of the object's projected area not hidden by nearer objects or the image edge.
    pub visible_fraction: f32,
    /// Its brake lights are on (the brake pedal is pressed).
    pub brake_lights: bool,
}

/// objects: ground truth, stamped with the same simulation time as the camera frame it
/// belongs to.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GroundTruthObjects {
    pub step: u64,
    pub objects: Vec<GroundTruthObject>,
}

impl Message for GroundTruthObjects {
    const KIND: MessageKind = MessageKind::GroundTruthObjects;
}

impl GroundTruthObject {
    /// The box the camera shows of it: none when it is outside the image or wholly hidden by
    /// nearer objects (`visible_fraction` 0), where a ground-truth box drawn over the image
    /// would read as a vehicle the detector missed.
    pub fn image_box(&self) -> Option<&BoundingBox2d> {
        self.bbox.as_ref().filter(|_| self.visible_fraction > 0.0)
    }
}

impl GroundTruthObjects {
    /// The nearest vehicle ahead of the ego whose centre is in `lane` (none off the road).
    pub fn nearest_ahead_in_lane(&self, lane: i32) -> Option<&GroundTruthObject> {
        self.objects
            .iter()
            .filter(|o| o.lane == lane && lane >= 0 && o.position_in_ego_m[0] > 0.0)
            .min_by(|a, b| a.position_in_ego_m[0].total_cmp(&b.position_in_ego_m[0]))
    }
}

/// One detected and tracked vehicle.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Detection {
    pub track_id: u32,
    pub class: ObjectClass,
    pub bbox: BoundingBox2d,
    /// 0..1
    pub confidence: f32,
    /// Longitudinal distance from the ego origin to the object's rear, along the ego x axis.
    pub distance_m: f64,
    /// Lateral offset of the object's centre, ego y axis (positive left).
    pub lateral_offset_m: f64,
    /// Object speed minus ego speed along ego x (negative: closing in).
    pub relative_speed_mps: f64,
    /// The expected error (one standard deviation) of `distance_m` and of
    /// `relative_speed_mps`, as the tracker estimates them: a new track's speed is unknown
    /// (tens of m/s) until a few frames have measured it, and far ranges are coarser.
    pub distance_sigma_m: f64,
    pub relative_speed_sigma_mps: f64,
    /// Its brake lights are seen lit in this frame.
    pub brake_lights: bool,
}

/// perception/objects: detections from one camera frame. The header's `stamp_sim_ns` is the
/// frame's simulation time; `frame_seq` is the frame's header seq.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Detections {
    pub frame_seq: u64,
    /// Wall-clock time the frame was published (its header's stamp_pub_ns), for latency.
    pub frame_stamp_pub_ns: u64,
    pub detections: Vec<Detection>,
}

impl Message for Detections {
    const KIND: MessageKind = MessageKind::Detections;
    fn check(&self) -> Result<(), Unsound> {
        for d in &self.detections {
            if !(0.0..=1.0).contains(&d.confidence) {
                return Err(Unsound(format!("track {}: confidence {} is outside 0..1", d.track_id, d.confidence)));
            }
            if !(d.distance_sigma_m >= 0.0 && d.relative_speed_sigma_mps >= 0.0) {
                return Err(Unsound(format!(
                    "track {}: standard deviations must be 0 or more (distance {}, relative speed {})",
                    d.track_id, d.distance_sigma_m, d.relative_speed_sigma_mps
                )));
            }
        }
        Ok(())
    }
}

pub(super) fn example_ground_truth() -> GroundTruthObjects {
    GroundTruthObjects {
        step: 125,
        objects: vec![GroundTruthObject {
            id: 3,
            class: ObjectClass::Car,
            size_m: [4.5, 1.8, 1.5],
            lane: 1,
            position_in_world_m: [61.25, -1.75, 0.0],
            yaw_in_world_rad: 0.0,
            velocity_in_world_mps: [25.0, 0.0, 0.0],
            position_in_ego_m: [27.75, 0.0, 0.0],
            yaw_in_ego_rad: 0.0,
            velocity_in_ego_mps: [-2.5, 0.0, 0.0],
            bbox: Some(BoundingBox2d { u_min_px: 300.0, v_min_px: 230.0, u_max_px: 340.0, v_max_px: 262.0 }),
            visible_fraction: 1.0,
            brake_lights: true,
        }],
    }
}

/// The Detections of docs/wire-format.md's byte example.
pub fn example_detections() -> Detections {
    Detections {
        frame_seq: 25,
        frame_stamp_pub_ns: 1_700_000_000_100_000_000,
        detections: vec![Detection {
            track_id: 1,
            class: ObjectClass::Car,
            bbox: BoundingBox2d { u_min_px: 301.0, v_min_px: 231.0, u_max_px: 339.0, v_max_px: 262.0 },
            confidence: 0.875,
            distance_m: 27.5,
            lateral_offset_m: 0.125,
            relative_speed_mps: -2.5,
            distance_sigma_m: 0.25,
            relative_speed_sigma_mps: 0.5,
            brake_lights: true,
        }],
    }
}
