//! Triangle rasterization into an RGB8 image, with near-plane clipping.
//!
//! Scanline fill with the pixel-centre rule: a pixel is inside when its centre (x + 0.5,
//! y + 0.5) is, so two triangles sharing an edge never both draw a pixel on it. Depth is
//! 1 / distance, which is linear in screen space; larger is nearer.

use nalgebra::Point3;

/// Closest distance in front of the camera that is drawn.
pub const NEAR_M: f64 = 0.1;

/// A projected vertex: pixel coordinates and inverse depth.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScreenVertex {
    pub u: f32,
    pub v: f32,
    pub inv_depth: f32,
}

/// The buffers one frame is drawn into.
pub struct Target<'a> {
    pub width: usize,
    pub height: usize,
    pub rgb: &'a mut [u8],
    /// Inverse depth of the nearest object drawn at each pixel (0: none).
    pub depth: &'a mut [f32],
    /// Which object (slot + 1) owns each pixel (0: none).
    pub owner: &'a mut [u16],
    /// Last coverage stamp at each pixel, to count an object's pixels once.
    pub stamps: &'a mut [u32],
}

/// How a triangle is drawn.
pub enum Layer<'c> {
    /// Painted over whatever is there (sky, grass, road, markings: all on the ground, drawn
    /// back to front before any object).
    Ground,
    /// Depth-tested against other objects; counts the pixels the object covers on its own.
    Object { owner: u16, stamp: u32, covered_px: &'c mut u32 },
}

/// Pinhole projection of camera-frame points (x forward, y left, z up).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Projection {
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
}

impl Projection {
    pub fn project(&self, p: &Point3<f64>) -> ScreenVertex {
        ScreenVertex {
            u: (self.cx - self.fx * p.y / p.x) as f32,
            v: (self.cy - self.fy * p.z / p.x) as f32,
            inv_depth: (1.0 / p.x) as f32,
        }
    }
}

/// Clips a convex polygon (camera frame) to the half-space in front of the near plane.
/// Returns the number of vertices written to `out` (0 when all is behind).
pub fn clip_near(polygon: &[Point3<f64>], out: &mut [Point3<f64>; 8]) -> usize {
    let mut n = 0;
    for i in 0..polygon.len() {
        let a = polygon[i];
        let b = polygon[(i + 1) % polygon.len()];
        let (a_in, b_in) = (a.x >= NEAR_M, b.x >= NEAR_M);
        if a_in && n < out.len() {
            out[n] = a;
            n += 1;
        }
        if a_in != b_in && n < out.len() {
            let t = (NEAR_M - a.x) / (b.x - a.x);
            out[n] = a + (b - a) * t;
            n += 1;
        }
    }
    n
}

/// Draws a convex polygon given in the camera frame: clipped, projected, fanned into triangles.
/// Returns the projected vertices' bounding box (u_min, v_min, u_max, v_max), if any.
pub fn fill_polygon(
    target: &mut Target<'_>,
    projection: &Projection,
    polygon: &[Point3<f64>],
    color: [u8; 3],
    layer: &mut Layer<'_>,
) -> Option<[f32; 4]> {
    let mut clipped = [Point3::origin(); 8];
    let n = clip_near(polygon, &mut clipped);
    if n < 3 {
        return None;
    }
    let mut screen = [ScreenVertex { u: 0.0, v: 0.0, inv_depth: 0.0 }; 8];
    let mut bounds = [f32::MAX, f32::MAX, f32::MIN, f32::MIN];
    for i in 0..n {
        let s = projection.project(&clipped[i]);
        bounds = [bounds[0].min(s.u), bounds[1].min(s.v), bounds[2].max(s.u), bounds[3].max(s.v)];
        screen[i] = s;
    }
    let off_image =
        bounds[2] < 0.0 || bounds[3] < 0.0 || bounds[0] > target.width as f32 || bounds[1] > target.height as f32;
    if !off_image {
        for i in 1..n - 1 {
            fill_triangle(target, [screen[0], screen[i], screen[i + 1]], color, layer);
        }
    }
    Some(bounds)
}

fn edge_u(a: &ScreenVertex, b: &ScreenVertex, v: f32) -> f32 {
    let dv = b.v - a.v;
    if dv.abs() < 1e-12 {
        a.u
    } else {
        a.u + (b.u - a.u) * (v - a.v) / dv
    }
}

/// Fills one triangle.
pub fn fill_triangle(target: &mut Target<'_>, mut tri: [ScreenVertex; 3], color: [u8; 3], layer: &mut Layer<'_>) {
    tri.sort_by(|a, b| a.v.total_cmp(&b.v));
    let [p0, p1, p2] = tri;
    let (du1, dv1, dw1) = (p1.u - p0.u, p1.v - p0.v, p1.inv_depth - p0.inv_depth);
    let (du2, dv2, dw2) = (p2.u - p0.u, p2.v - p0.v, p2.inv_depth - p0.inv_depth);
    let det = du1 * dv2 - du2 * dv1;
    if det.abs() < 1e-6 || !det.is_finite() {
        return;
    }
    // Inverse depth as a plane over the screen: w = a u + b v + c.
    let a = (dw1 * dv2 - dw2 * dv1) / det;
    let b = (du1 * dw2 - du2 * dw1) / det;
    let c = p0.inv_depth - a * p0.u - b * p0.v;

    let (w, h) = (target.width as i64, target.height as i64);
    let y_start = ((p0.v - 0.5).ceil() as i64).clamp(0, h);
    let y_end = ((p2.v - 0.5).ceil() as i64).clamp(0, h);
    for y in y_start..y_end {
        let yc = y as f32 + 0.5;
        let ua = edge_u(&p0, &p2, yc);
        let ub = if yc < p1.v { edge_u(&p0, &p1, yc) } else { edge_u(&p1, &p2, yc) };
        let (ul, ur) = if ua < ub { (ua, ub) } else { (ub, ua) };
        let x0 = ((ul - 0.5).ceil() as i64).clamp(0, w) as usize;
        let x1 = ((ur - 0.5).ceil() as i64).clamp(0, w) as usize;
        if x0 >= x1 {
            continue;
        }
        let row = y as usize * target.width;
        match layer {
            Layer::Ground => {
                for px in target.rgb[(row + x0) * 3..(row + x1) * 3].chunks_exact_mut(3) {
                    px.copy_from_slice(&color);
                }
            }
            Layer::Object { owner, stamp, covered_px } => {
                let mut depth = a * (x0 as f32 + 0.5) + b * yc + c;
                for x in x0..x1 {
                    let i = row + x;
                    if target.stamps[i] != *stamp {
                        target.stamps[i] = *stamp;
                        **covered_px += 1;
                    }
                    if depth > target.depth[i] {
                        target.depth[i] = depth;
                        target.owner[i] = *owner;
                        target.rgb[i * 3..i * 3 + 3].copy_from_slice(&color);
                    }
                    depth += a;
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    struct Buffers {
        rgb: Vec<u8>,
        depth: Vec<f32>,
        owner: Vec<u16>,
        stamps: Vec<u32>,
    }

    impl Buffers {
        fn new(w: usize, h: usize) -> Self {
            Buffers { rgb: vec![0; w * h * 3], depth: vec![0.0; w * h], owner: vec![0; w * h], stamps: vec![0; w * h] }
        }
        fn target(&mut self, w: usize, h: usize) -> Target<'_> {
            Target {
                width: w,
                height: h,
                rgb: &mut self.rgb,
                depth: &mut self.depth,
                owner: &mut self.owner,
                stamps: &mut self.stamps,
            }
        }
    }

    fn v(u: f32, v: f32, inv_depth: f32) -> ScreenVertex {
        ScreenVertex { u, v, inv_depth }
    }

    #[test]
    fn two_triangles_of_a_square_cover_each_pixel_once() {
        let mut b = Buffers::new(10, 10);
        let mut covered = 0;
        let mut t = b.target(10, 10);
        let mut layer = Layer::Object { owner: 1, stamp: 1, covered_px: &mut covered };
        fill_triangle(&mut t, [v(2.0, 2.0, 1.0), v(8.0, 2.0, 1.0), v(8.0, 8.0, 1.0)], [9, 9, 9], &mut layer);
        fill_triangle(&mut t, [v(2.0, 2.0, 1.0), v(8.0, 8.0, 1.0), v(2.0, 8.0, 1.0)], [9, 9, 9], &mut layer);
        assert_eq!(covered, 36);
        assert_eq!(b.owner.iter().filter(|o| **o == 1).count(), 36);
    }

    #[test]
    fn nearer_object_wins_whatever_the_order() {
        let mut b = Buffers::new(4, 4);
        let (mut far_px, mut near_px) = (0, 0);
        let mut t = b.target(4, 4);
        let full = |w| [v(0.0, 0.0, w), v(8.0, 0.0, w), v(0.0, 8.0, w)];
        fill_triangle(
            &mut t,
            full(0.5),
            [1, 1, 1],
            &mut Layer::Object { owner: 2, stamp: 2, covered_px: &mut near_px },
        );
        fill_triangle(&mut t, full(0.1), [2, 2, 2], &mut Layer::Object { owner: 1, stamp: 1, covered_px: &mut far_px });
        assert!(b.owner.iter().all(|o| *o == 2));
        assert_eq!((near_px, far_px), (16, 16));
    }

    #[test]
    fn clipping_keeps_the_part_in_front() {
        let quad = [
            Point3::new(-1.0, -1.0, 0.0),
            Point3::new(5.0, -1.0, 0.0),
            Point3::new(5.0, 1.0, 0.0),
            Point3::new(-1.0, 1.0, 0.0),
        ];
        let mut out = [Point3::origin(); 8];
        let n = clip_near(&quad, &mut out);
        assert_eq!(n, 4);
        assert!(out[..n].iter().all(|p| p.x >= NEAR_M - 1e-12));
        let behind = quad.map(|p| Point3::new(-p.x.abs() - 1.0, p.y, p.z));
        assert_eq!(clip_near(&behind, &mut out), 0);
    }
}
