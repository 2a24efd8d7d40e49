//! Camera geometry for perception: pixels to rays in the ego body frame, the ground plane,
//! and distances from a contact row or a known width. Same conventions as
//! `camera/front/info` (docs/simulator.md): camera x forward, y left, z up; u right, v down.

use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};

use slipstream_contract::msg::CameraInfo;

/// A calibrated camera on the ego.
#[derive(Debug, Clone)]
pub struct CameraModel {
    pub info: CameraInfo,
    body_from_camera: Isometry3<f64>,
}

impl CameraModel {
    pub fn new(info: &CameraInfo) -> CameraModel {
        let [roll, pitch, yaw] = info.mount_roll_pitch_yaw_rad;
        let [x, y, z] = info.mount_position_in_ego_m;
        let body_from_camera =
            Isometry3::from_parts(Translation3::new(x, y, z), UnitQuaternion::from_euler_angles(roll, pitch, yaw));
        CameraModel { info: info.clone(), body_from_camera }
    }

    /// Camera centre in the body frame.
    pub(crate) fn origin_in_body(&self) -> Point3<f64> {
        self.body_from_camera * Point3::origin()
    }

    /// Direction (not normalized) of the ray through pixel coordinates (u, v), body frame.
    pub(crate) fn ray_in_body(&self, u: f64, v: f64) -> Vector3<f64> {
        let i = &self.info;
        self.body_from_camera * Vector3::new(1.0, (i.cx_px - u) / i.fx_px, (i.cy_px - v) / i.fy_px)
    }

    /// The ground point (body frame, z = 0) seen at (u, v), or None at or above the horizon.
    pub fn ground_point(&self, u: f64, v: f64) -> Option<Point3<f64>> {
        let o = self.origin_in_body();
        let r = self.ray_in_body(u, v);
        (r.z < -1e-9).then(|| o + r * (-o.z / r.z))
    }

    /// The image row of the horizon at the image centre column (a flat world).
    pub fn horizon_v(&self) -> f64 {
        // Solve ray_in_body(cx, v).z = 0: the row whose ray is level.
        let (lo, hi) = (-(self.info.height as f64) * 4.0, self.info.height as f64 * 5.0);
        let z = |v: f64| self.ray_in_body(self.info.cx_px, v).z;
        let (mut a, mut b) = (lo, hi);
        for _ in 0..60 {
            let m = (a + b) / 2.0;
            if z(m) > 0.0 {
                a = m;
            } else {
                b = m;
            }
        }
        (a + b) / 2.0
    }

    /// Lateral offset (body y) of the point at column `u` on a surface `x_m` ahead, row `v`.
    pub(crate) fn lateral_at(&self, u: f64, v: f64, x_m: f64) -> f64 {
        let o = self.origin_in_body();
        let r = self.ray_in_body(u, v);
        o.y + (x_m - o.x) * r.y / r.x
    }

    /// Image position of a body-frame point, if in front of the camera.
    pub fn project(&self, p: &Point3<f64>) -> Option<(f64, f64)> {
        let c = self.body_from_camera.inverse() * p;
        (c.x > 1e-6)
            .then(|| (self.info.cx_px - self.info.fx_px * c.y / c.x, self.info.cy_px - self.info.fy_px * c.z / c.x))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use slipstream_contract::msg::ImageEncoding;

    fn camera() -> CameraModel {
        CameraModel::new(&CameraInfo::pinhole(
            640,
            480,
            60f64.to_radians(),
            [1.6, 0.0, 1.35],
            [0.0, 0.05, 0.0],
            20.0,
            ImageEncoding::Rgb8,
        ))
    }

    #[test]
    fn ground_points_and_projections_invert_each_other() {
        let cam = camera();
        for p in [Point3::new(10.0, 1.5, 0.0), Point3::new(45.0, -3.5, 0.0), Point3::new(80.0, 0.0, 0.0)] {
            let (u, v) = cam.project(&p).unwrap();
            let g = cam.ground_point(u, v).unwrap();
            assert!((g - p).norm() < 1e-9, "{p} -> ({u}, {v}) -> {g}");
        }
        let h = cam.horizon_v();
        assert!(cam.ground_point(320.0, h - 1.0).is_none() && cam.ground_point(320.0, h + 1.0).is_some());
        // Pitched down 0.05 rad: the horizon is above the image centre by f tan(0.05).
        assert!((h - (240.0 - 554.256 * 0.05f64.tan())).abs() < 0.1, "horizon {h}");
    }

    #[test]
    fn a_point_at_a_known_distance_gives_its_lateral_offset() {
        let cam = camera();
        for (x, y, z) in [(30.0, 0.6, 0.8), (12.0, -1.2, 0.3), (80.0, 2.5, 1.1)] {
            let (u, v) = cam.project(&Point3::new(x, y, z)).unwrap();
            assert!((cam.lateral_at(u, v, x) - y).abs() < 1e-9, "({x}, {y}, {z})");
        }
    }
}
