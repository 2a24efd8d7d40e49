//! The front camera, rendered in software.
//!
//! A frame is drawn in layers: a sky gradient, then the ground (grass, the road surface, lane
//! markings and each vehicle's shadow; markings and shadows with anti-aliased edges, so that
//! where they begin can be measured to a fraction of a pixel) painted back to front, then the vehicles as shaded
//! boxes (body, cabin with glass, wheels, tail lights) with a depth buffer between them. The
//! ground is flat and every vehicle stands on it, so a vehicle's pixel is always in front of
//! the ground: only vehicles need depth testing. While drawing, the renderer records which
//! vehicle owns each pixel; that gives ground truth its 2D boxes and visible fractions for
//! the very frame published. Optional brightness changes and pixel noise come last.

mod raster;
mod scene;

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};

use self::raster::{fill_polygon, fill_polygon_smooth, Layer, Projection, Target};
use super::rng::SimRng;
use super::world::VehicleView;
use slipstream_contract::msg::{BoundingBox2d, CameraInfo};
use slipstream_model::road::Road;

/// What the renderer found out about one vehicle while drawing it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ObjectVisibility {
    pub id: u32,
    /// Box in the image (clamped to it), None when no part projects into the image.
    pub bbox: Option<BoundingBox2d>,
    /// Pixels of it in the final image.
    pub visible_px: u32,
    /// (visible pixels / pixels it covers alone) x (share of its box inside the image).
    pub visible_fraction: f32,
}

/// Visibility over two cameras: the first camera's boxes (its image is the one boxes refer
/// to), each vehicle's visible fraction the larger of the two (a vehicle 150 m ahead is a few
/// pixels in a wide camera, whole in a narrow one).
pub(crate) fn seen_by_either(mut first: Vec<ObjectVisibility>, second: &[ObjectVisibility]) -> Vec<ObjectVisibility> {
    for v in &mut first {
        if let Some(o) = second.iter().find(|o| o.id == v.id) {
            v.visible_fraction = v.visible_fraction.max(o.visible_fraction);
        }
    }
    first
}

/// Brightness and noise for one frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameLook {
    /// Multiplies every channel.
    pub brightness: f32,
    /// Where in the noise table this frame's noise starts.
    pub noise_offset: usize,
}

impl FrameLook {
    pub const PLAIN: FrameLook = FrameLook { brightness: 1.0, noise_offset: 0 };
}

/// Renders frames of one camera; keeps its buffers between frames.
pub struct Renderer {
    info: CameraInfo,
    projection: Projection,
    /// Body frame -> camera frame.
    camera_from_body: Isometry3<f64>,
    sky: Vec<u8>,
    depth: Vec<f32>,
    owner: Vec<u16>,
    stamps: Vec<u32>,
    next_stamp: u32,
    /// Gaussian pixel noise (empty when off), indexed from each frame's offset.
    noise: Vec<i8>,
    /// Vehicles beyond this distance are not drawn.
    pub draw_distance_m: f64,
}

/// A vehicle's visibility in a `w` x `h` frame: its projected `bounds` (u0, v0, u1, v1,
/// possibly beyond the image), the pixels its faces covered when drawn and the pixels still
/// its own at the end. The fraction is unoccluded share x share inside the image.
fn visibility(
    id: u32,
    bounds: Option<[f32; 4]>,
    covered_px: u32,
    visible_px: u32,
    w: usize,
    h: usize,
) -> ObjectVisibility {
    let (wf, hf) = (w as f32, h as f32);
    let hidden = ObjectVisibility { id, bbox: None, visible_px, visible_fraction: 0.0 };
    let Some([u0, v0, u1, v1]) = bounds else { return hidden };
    let clamped = BoundingBox2d {
        u_min_px: u0.clamp(0.0, wf),
        v_min_px: v0.clamp(0.0, hf),
        u_max_px: u1.clamp(0.0, wf),
        v_max_px: v1.clamp(0.0, hf),
    };
    let area = |b: [f32; 4]| ((b[2] - b[0]) * (b[3] - b[1])).max(0.0);
    let inside = area([clamped.u_min_px, clamped.v_min_px, clamped.u_max_px, clamped.v_max_px]);
    if inside <= 0.0 {
        return hidden;
    }
    let in_image = inside / area([u0, v0, u1, v1]).max(f32::MIN_POSITIVE);
    let unoccluded = if covered_px == 0 { 0.0 } else { visible_px as f32 / covered_px as f32 };
    ObjectVisibility { id, bbox: Some(clamped), visible_px, visible_fraction: (unoccluded * in_image).clamp(0.0, 1.0) }
}

impl Renderer {
    /// A renderer for the camera `info` describes; `noise_stddev` > 0 adds pixel noise drawn
    /// from `rng`.
    pub fn new(info: &CameraInfo, noise_stddev: f64, rng: &mut SimRng) -> Renderer {
        let (w, h) = (info.width as usize, info.height as usize);
        let [roll, pitch, yaw] = info.mount_roll_pitch_yaw_rad;
        let [x, y, z] = info.mount_position_in_ego_m;
        let body_from_camera =
            Isometry3::from_parts(Translation3::new(x, y, z), UnitQuaternion::from_euler_angles(roll, pitch, yaw));
        let mut sky = Vec::with_capacity(w * h * 3);
        for row in 0..h {
            let t = row as f32 / h as f32;
            let c = [110.0 + 90.0 * t, 160.0 + 60.0 * t, 225.0 + 15.0 * t].map(|c: f32| c.min(255.0) as u8);
            for _ in 0..w {
                sky.extend_from_slice(&c);
            }
        }
        let noise = if noise_stddev > 0.0 {
            (0..(1 << 16)).map(|_| rng.normal(noise_stddev).round().clamp(-127.0, 127.0) as i8).collect()
        } else {
            Vec::new()
        };
        Renderer {
            info: info.clone(),
            projection: Projection { fx: info.fx_px, fy: info.fy_px, cx: info.cx_px, cy: info.cy_px },
            camera_from_body: body_from_camera.inverse(),
            sky,
            depth: vec![0.0; w * h],
            owner: vec![0; w * h],
            stamps: vec![0; w * h],
            next_stamp: 1,
            noise,
            draw_distance_m: 400.0,
        }
    }

    /// The camera of a run with `seed`: its pixel noise and the generator of each frame's
    /// look both come from the seed, so every consumer (the node, `eval`, `--preview`) draws
    /// the same frames for the same run.
    pub fn seeded(info: &CameraInfo, noise_stddev: f64, seed: u64) -> (Renderer, SimRng) {
        (Renderer::new(info, noise_stddev, &mut SimRng::new(seed ^ 0xCA3E_2A00)), SimRng::new(seed ^ 0x1006_0000))
    }

    /// The narrow camera of a run with `seed`: seeded like [`Renderer::seeded`], with noise of
    /// its own.
    pub(crate) fn seeded_narrow(info: &CameraInfo, noise_stddev: f64, seed: u64) -> (Renderer, SimRng) {
        Renderer::seeded(info, noise_stddev, seed ^ 0x4E52_0000_0000)
    }

    pub fn info(&self) -> &CameraInfo {
        &self.info
    }

    /// Bytes of one RGB8 frame.
    pub fn frame_len(&self) -> usize {
        self.info.width as usize * self.info.height as usize * 3
    }

    /// Draws the view from `ego` into `rgb` (width x height x 3 bytes, row-major, top row
    /// first) and reports every other vehicle's visibility.
    pub fn render(
        &mut self,
        road: &Road,
        ego: &VehicleView,
        vehicles: &[VehicleView],
        look: FrameLook,
        rgb: &mut [u8],
    ) -> Vec<ObjectVisibility> {
        assert_eq!(rgb.len(), self.frame_len(), "frame buffer size");
        let (w, h) = (self.info.width as usize, self.info.height as usize);
        let world_from_body = body_pose(ego);
        let camera_from_world = self.camera_from_body * world_from_body.inverse();

        rgb.copy_from_slice(&self.sky);
        self.depth.fill(0.0);
        self.owner.fill(0);
        let mut target = Target {
            width: w,
            height: h,
            rgb,
            depth: &mut self.depth,
            owner: &mut self.owner,
            stamps: &mut self.stamps,
        };
        let projection = self.projection;

        // Ground layer, back to front: grass, road, markings, shadows.
        let mut draw_ground = |quad: &[nalgebra::Point3<f64>; 4], color: [u8; 3], smooth: bool| {
            let camera_quad = quad.map(|p| camera_from_world * p);
            if smooth {
                fill_polygon_smooth(&mut target, &projection, &camera_quad, color);
            } else {
                fill_polygon(&mut target, &projection, &camera_quad, color, &mut Layer::Ground);
            }
        };
        for quad in scene::ground(road, ego) {
            draw_ground(&quad.corners, quad.color, quad.smooth);
        }
        let in_range: Vec<&VehicleView> = vehicles
            .iter()
            .filter(|v| v.id != ego.id && (v.rear_axle - ego.rear_axle).norm() < self.draw_distance_m)
            .collect();
        for v in &in_range {
            // Smooth: where a vehicle meets the road lies between pixel rows, as in a real camera.
            draw_ground(&scene::shadow(v), scene::SHADOW, true);
        }

        // Objects, depth-tested.
        let mut found = Vec::with_capacity(in_range.len());
        for (slot, v) in in_range.iter().enumerate() {
            let camera_from_vehicle = camera_from_world * body_pose(v);
            let camera_in_vehicle = camera_from_vehicle.inverse() * nalgebra::Point3::origin();
            let stamp = self.next_stamp;
            self.next_stamp = self.next_stamp.wrapping_add(1).max(1);
            let mut covered_px = 0u32;
            let mut bounds: Option<[f32; 4]> = None;
            for face in scene::vehicle_faces(v) {
                if !face.faces(&camera_in_vehicle) {
                    continue;
                }
                let color = face.shaded(v.yaw_rad);
                let polygon = face.corners.map(|p| camera_from_vehicle * p);
                let mut layer = Layer::Object { owner: slot as u16 + 1, stamp, covered_px: &mut covered_px };
                if let Some(b) = fill_polygon(&mut target, &projection, &polygon, color, &mut layer) {
                    bounds = Some(match bounds {
                        None => b,
                        Some(a) => [a[0].min(b[0]), a[1].min(b[1]), a[2].max(b[2]), a[3].max(b[3])],
                    });
                }
            }
            found.push((v.id, bounds, covered_px));
        }

        let mut visible = vec![0u32; in_range.len() + 1];
        for &o in target.owner.iter() {
            visible[o as usize] += 1;
        }
        apply_look(&self.noise, look, target.rgb);

        found
            .into_iter()
            .enumerate()
            .map(|(slot, (id, bounds, covered_px))| visibility(id, bounds, covered_px, visible[slot + 1], w, h))
            .collect()
    }

    /// Draws a frame's look for a frame: brightness within 1 +- `amplitude`, a noise offset.
    pub fn draw_look(&self, amplitude: f64, rng: &mut SimRng) -> FrameLook {
        let brightness = if amplitude > 0.0 { rng.range(1.0 - amplitude, 1.0 + amplitude) as f32 } else { 1.0 };
        let noise_offset = if self.noise.is_empty() { 0 } else { rng.below(self.noise.len() as u64) as usize };
        FrameLook { brightness, noise_offset }
    }
}

/// Brightness (a lookup table, skipped at 1) and noise (the table read from this frame's
/// offset in contiguous runs, so the add vectorizes).
fn apply_look(noise: &[i8], look: FrameLook, rgb: &mut [u8]) {
    if look.brightness != 1.0 {
        let lut: [u8; 256] = std::array::from_fn(|i| (i as f32 * look.brightness).round().clamp(0.0, 255.0) as u8);
        rgb.iter_mut().for_each(|p| *p = lut[*p as usize]);
    }
    if noise.is_empty() {
        return;
    }
    let mut at = look.noise_offset % noise.len();
    let mut rest = rgb;
    while !rest.is_empty() {
        let run = (noise.len() - at).min(rest.len());
        let (head, tail) = rest.split_at_mut(run);
        for (p, n) in head.iter_mut().zip(&noise[at..at + run]) {
            *p = p.saturating_add_signed(*n);
        }
        rest = tail;
        at = 0;
    }
}

/// World pose of a vehicle's body frame (rear axle on the ground, x forward).
fn body_pose(v: &VehicleView) -> Isometry3<f64> {
    Isometry3::new(Vector3::new(v.rear_axle.x, v.rear_axle.y, 0.0), Vector3::new(0.0, 0.0, v.yaw_rad))
}

#[cfg(test)]
mod tests;
