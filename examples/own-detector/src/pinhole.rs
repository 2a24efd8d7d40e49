//! The camera of camera/front/info as a pinhole (mount roll and yaw taken as 0): where a pixel
//! meets the flat road and where a point lands in the image; and the dark bands of a mask.
//! Body frame: x forward from the rear axle, y left, z up; pixels u right, v down.

use slipstream_contract::msg::{BoundingBox2d, CameraInfo};

pub(crate) struct Pinhole<'a> {
    info: &'a CameraInfo,
    pitch: f64,
}

impl<'a> Pinhole<'a> {
    pub(crate) fn new(info: &'a CameraInfo) -> Self {
        Pinhole { info, pitch: info.mount_roll_pitch_yaw_rad[1] }
    }

    /// The image row of the horizon.
    pub(crate) fn horizon_v(&self) -> f64 {
        self.info.cy_px - self.info.fy_px * self.pitch.tan()
    }

    /// The road point (x, y) pixel (u, v) sees, None at or above the horizon.
    pub(crate) fn ground(&self, u: f64, v: f64) -> Option<(f64, f64)> {
        let (i, m) = (self.info, self.info.mount_position_in_ego_m);
        let a = (i.cy_px - v) / i.fy_px;
        let (s, c) = self.pitch.sin_cos();
        if s - a * c <= 1e-9 {
            return None;
        }
        let pz = -m[2];
        let px = -pz * (c + a * s) / (s - a * c);
        let depth = px * c - pz * s;
        Some((px + m[0], -(u - i.cx_px) * depth / i.fx_px + m[1]))
    }

    /// The pixel of a body-frame point, None behind the camera.
    pub(crate) fn project(&self, x: f64, y: f64, z: f64) -> Option<(f64, f64)> {
        let (i, m) = (self.info, self.info.mount_position_in_ego_m);
        let (px, py, pz) = (x - m[0], y - m[1], z - m[2]);
        let (s, c) = self.pitch.sin_cos();
        let depth = px * c - pz * s;
        if depth < 0.5 {
            return None;
        }
        let up = px * s + pz * c;
        Some((i.cx_px - i.fx_px * py / depth, i.cy_px - i.fy_px * up / depth))
    }

    /// The image box of a vehicle's rear face centred at (x, y) on the road, clipped to the
    /// image; None when none of it is inside.
    pub(crate) fn rear_box(&self, x: f64, y: f64, width_m: f64, height_m: f64) -> Option<BoundingBox2d> {
        let (u0, v0) = self.project(x, y + width_m / 2.0, height_m)?;
        let (u1, v1) = self.project(x, y - width_m / 2.0, 0.0)?;
        let (w, h) = (self.info.width as f64, self.info.height as f64);
        let (cu0, cv0, cu1, cv1) = (u0.max(0.0), v0.max(0.0), u1.min(w), v1.min(h));
        (cu1 > cu0 && cv1 > cv0).then_some(BoundingBox2d {
            u_min_px: cu0 as f32,
            v_min_px: cv0 as f32,
            u_max_px: cu1 as f32,
            v_max_px: cv1 as f32,
        })
    }
}

/// The connected dark regions of `mask` (rows of `width`), each as its columns (first, last)
/// and its lowest row: 4-connected, so that single noisy pixels touching at a corner do not
/// chain into a band a vehicle wide.
pub(crate) fn bands(mask: &[bool], width: usize) -> Vec<(usize, usize, usize)> {
    let rows = mask.len() / width.max(1);
    let mut label = vec![false; mask.len()];
    let mut out = Vec::new();
    for start in 0..mask.len() {
        if !mask[start] || label[start] {
            continue;
        }
        let (mut u0, mut u1, mut v1) = (usize::MAX, 0, 0);
        let mut todo = vec![start];
        label[start] = true;
        while let Some(p) = todo.pop() {
            let (u, v) = (p % width, p / width);
            (u0, u1, v1) = (u0.min(u), u1.max(u), v1.max(v));
            let left = (u > 0).then(|| p - 1);
            let right = (u + 1 < width).then_some(p + 1);
            let up = (v > 0).then(|| p - width);
            let down = (v + 1 < rows).then_some(p + width);
            for q in [left, right, up, down].into_iter().flatten() {
                if mask[q] && !label[q] {
                    label[q] = true;
                    todo.push(q);
                }
            }
        }
        out.push((u0, u1, v1));
    }
    out
}
