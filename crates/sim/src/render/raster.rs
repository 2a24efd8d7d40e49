//! Triangle rasterization into an RGB8 image, with near-plane clipping.
//!
//! Scanline fill with the pixel-centre rule: a pixel is inside when its centre (x + 0.5,
//! y + 0.5) is, so two triangles sharing an edge never both draw a pixel on it. Depth is
//! 1 / distance, which is linear in screen space; larger is nearer.

use nalgebra::Point3;

/// Closest distance in front of the camera that is drawn.
pub(super) const NEAR_M: f64 = 0.1;

/// A projected vertex: pixel coordinates and inverse depth.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct ScreenVertex {
    pub u: f32,
    pub v: f32,
    pub inv_depth: f32,
}

/// The buffers one frame is drawn into.
pub(super) struct Target<'a> {
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
pub(super) enum Layer<'c> {
    /// Painted over whatever is there (sky, grass, road, markings: all on the ground, drawn
    /// back to front before any object).
    Ground,
    /// Depth-tested against other objects; counts the pixels the object covers on its own.
    Object { owner: u16, stamp: u32, covered_px: &'c mut u32 },
}

/// Pinhole projection of camera-frame points (x forward, y left, z up).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Projection {
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
}

impl Projection {
    /// Pixel coordinates (u, v) of a point in front of the camera.
    pub(super) fn uv(&self, p: &Point3<f64>) -> (f64, f64) {
        (self.cx - self.fx * p.y / p.x, self.cy - self.fy * p.z / p.x)
    }

    pub(super) fn project(&self, p: &Point3<f64>) -> ScreenVertex {
        let (u, v) = self.uv(p);
        ScreenVertex { u: u as f32, v: v as f32, inv_depth: (1.0 / p.x) as f32 }
    }
}

/// Clips a convex polygon (camera frame) to the half-space in front of the near plane.
/// Returns the number of vertices written to `out` (0 when all is behind).
pub(super) fn clip_near(polygon: &[Point3<f64>], out: &mut [Point3<f64>; 8]) -> usize {
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
pub(super) fn fill_polygon(
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

/// Keeps the part of a convex polygon (screen coordinates) on one side of an axis-aligned
/// line: `axis` 0 is u, 1 is v; `keep_above` keeps coordinates >= `at`.
fn clip_axis(poly: &[(f64, f64)], axis: usize, at: f64, keep_above: bool, out: &mut Vec<(f64, f64)>) {
    out.clear();
    let coord = |p: (f64, f64)| if axis == 0 { p.0 } else { p.1 };
    let inside = |p: (f64, f64)| (coord(p) >= at) == keep_above;
    for i in 0..poly.len() {
        let (a, b) = (poly[i], poly[(i + 1) % poly.len()]);
        if inside(a) {
            out.push(a);
        }
        if inside(a) != inside(b) {
            let t = (at - coord(a)) / (coord(b) - coord(a));
            out.push((a.0 + (b.0 - a.0) * t, a.1 + (b.1 - a.1) * t));
        }
    }
}

/// Area of a simple polygon (shoelace).
fn area(poly: &[(f64, f64)]) -> f64 {
    let mut twice = 0.0;
    for i in 0..poly.len() {
        let (a, b) = (poly[i], poly[(i + 1) % poly.len()]);
        twice += a.0 * b.1 - b.0 * a.1;
    }
    twice.abs() / 2.0
}

/// Where a convex polygon crosses the line v = `at`: its span (u_min, u_max), if any.
fn span_at(poly: &[(f64, f64)], at: f64) -> Option<(f64, f64)> {
    let (mut l, mut r) = (f64::MAX, f64::MIN);
    for i in 0..poly.len() {
        let (a, b) = (poly[i], poly[(i + 1) % poly.len()]);
        if (a.1 <= at) != (b.1 <= at) || (a.1 == at && b.1 == at) {
            let u = if b.1 == a.1 { a.0.min(b.0) } else { a.0 + (b.0 - a.0) * (at - a.1) / (b.1 - a.1) };
            let u2 = if b.1 == a.1 { a.0.max(b.0) } else { u };
            l = l.min(u);
            r = r.max(u2);
        }
    }
    (l <= r).then_some((l, r))
}

/// Paints a convex polygon given in the camera frame over what is drawn, with anti-aliased
/// edges: each pixel is blended with `color` by the exact share of its area the polygon
/// covers. No depth, no owner: for ground detail (shadows, markings), whose edges then fall
/// between pixel rows as a real camera's do, so a consumer can locate them to a fraction of
/// a pixel. Returns the projected bounding box like `fill_polygon`.
pub(super) fn fill_polygon_smooth(
    target: &mut Target<'_>,
    projection: &Projection,
    polygon: &[Point3<f64>],
    color: [u8; 3],
) -> Option<[f32; 4]> {
    let mut clipped = [Point3::origin(); 8];
    let n = clip_near(polygon, &mut clipped);
    if n < 3 {
        return None;
    }
    // In f64: edges are located to far less than the f32 of ScreenVertex.
    let screen: Vec<(f64, f64)> = clipped[..n].iter().map(|p| projection.uv(p)).collect();
    let mut bounds = [f32::MAX, f32::MAX, f32::MIN, f32::MIN];
    for &(u, v) in &screen {
        let (u, v) = (u as f32, v as f32);
        bounds = [bounds[0].min(u), bounds[1].min(v), bounds[2].max(u), bounds[3].max(v)];
    }
    let (w, h) = (target.width as i64, target.height as i64);
    let y0 = (bounds[1].floor() as i64).clamp(0, h);
    let y1 = (bounds[3].ceil() as i64).clamp(0, h);
    if bounds[2] < 0.0 || bounds[0] > w as f32 || y0 >= y1 {
        return Some(bounds);
    }
    let (mut upper, mut strip, mut left, mut cell) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for y in y0..y1 {
        let (top, bottom) = (y as f64, y as f64 + 1.0);
        clip_axis(&screen, 1, top, true, &mut upper);
        clip_axis(&upper, 1, bottom, false, &mut strip);
        if strip.len() < 3 {
            continue;
        }
        let u_min = strip.iter().map(|p| p.0).fold(f64::MAX, f64::min);
        let u_max = strip.iter().map(|p| p.0).fold(f64::MIN, f64::max);
        // Pixels inside the polygon's span on both the row's top and bottom lines are covered
        // whole (its left boundary is convex, its right concave): painted, the rest blended.
        let (solid0, solid1) = match (span_at(&screen, top), span_at(&screen, bottom)) {
            (Some(a), Some(b)) => (a.0.max(b.0).ceil() as i64, a.1.min(b.1).floor() as i64),
            _ => (0, 0),
        };
        let x0 = (u_min.floor() as i64).clamp(0, w);
        let x1 = (u_max.ceil() as i64).clamp(0, w);
        let row = y as usize * target.width;
        for x in x0..x1 {
            let i = (row + x as usize) * 3;
            let px = &mut target.rgb[i..i + 3];
            if x >= solid0 && x < solid1 {
                px.copy_from_slice(&color);
                continue;
            }
            clip_axis(&strip, 0, x as f64, true, &mut left);
            clip_axis(&left, 0, x as f64 + 1.0, false, &mut cell);
            let share = if cell.len() < 3 { 0.0 } else { area(&cell).min(1.0) as f32 };
            for (p, c) in px.iter_mut().zip(color) {
                *p = (*p as f32 + (c as f32 - *p as f32) * share).round() as u8;
            }
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
pub(super) fn fill_triangle(
    target: &mut Target<'_>,
    mut tri: [ScreenVertex; 3],
    color: [u8; 3],
    layer: &mut Layer<'_>,
) {
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
    fn a_smooth_edge_blends_the_pixel_it_crosses_by_the_share_it_covers() {
        let (w, h) = (8, 8);
        let mut b = Buffers::new(w, h);
        let projection = Projection { fx: 1.0, fy: 1.0, cx: 0.0, cy: 0.0 };
        // A square at depth 1 spanning u 1.0..6.0 and v 2.0..5.3: its lower edge covers 30% of
        // row 5, its sides fall on pixel boundaries.
        let at = |u: f64, v: f64| Point3::new(1.0, -u, -v);
        let square = [at(1.0, 2.0), at(6.0, 2.0), at(6.0, 5.3), at(1.0, 5.3)];
        fill_polygon_smooth(&mut b.target(w, h), &projection, &square, [200, 100, 0]);
        let px = |x: usize, y: usize| &b.rgb[(y * w + x) * 3..(y * w + x) * 3 + 3];
        assert_eq!(px(3, 3), [200, 100, 0], "inside");
        assert_eq!(px(0, 3), [0, 0, 0], "left of it");
        assert_eq!(px(3, 6), [0, 0, 0], "below it");
        let share = px(3, 5)[0] as f32 / 200.0;
        assert!((share - 0.3).abs() <= 0.5 / 200.0, "row 5 holds {share} of the colour");
        assert_eq!(px(3, 5)[1] as f32, (100.0 * share).round(), "every channel by the same share");
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
