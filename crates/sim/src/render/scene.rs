//! What the camera sees, as flat polygons: the ground (grass, road, markings, shadows) in the
//! world frame and each vehicle as shaded boxes in its body frame.

use nalgebra::{Point3, Vector3};

use super::super::world::VehicleView;
use slipstream_contract::msg::ObjectClass;
use slipstream_model::road::Road;

const GRASS: [u8; 3] = [78, 118, 62];
const ASPHALT: [u8; 3] = [84, 84, 88];
const MARKING: [u8; 3] = [228, 228, 222];
pub(super) const SHADOW: [u8; 3] = [42, 42, 46];
const GLASS: [u8; 3] = [38, 50, 62];
const TYRE: [u8; 3] = [22, 22, 22];
const TAIL_LIGHT: [u8; 3] = [205, 25, 25];
/// Tail lights when braking: they emit, so the sun's shading does not dim them (no lit body
/// face reaches this red: its red is at most 255 x the light, with green and blue far below).
pub(super) const BRAKE_LIGHT: [u8; 3] = [255, 42, 30];
/// A rider's clothing.
const RIDER: [u8; 3] = [48, 50, 58];
const TRIM: [u8; 3] = [35, 35, 38];

/// Road visible ahead of the ego, and markings (finer detail) up to here.
const ROAD_AHEAD_M: f64 = 400.0;
const MARKINGS_AHEAD_M: f64 = 160.0;
const DASH_M: f64 = 3.0;
const DASH_PERIOD_M: f64 = 12.0;
const MARKING_WIDTH_M: f64 = 0.15;
const SHOULDER_M: f64 = 0.6;

/// A polygon on the ground, in the world frame.
pub(super) struct GroundQuad {
    pub corners: [Point3<f64>; 4],
    pub color: [u8; 3],
    /// Drawn with anti-aliased edges (detail a consumer locates to a fraction of a pixel:
    /// markings); large surfaces that tile the ground are drawn without, so that no seam
    /// shows where two of them meet.
    pub smooth: bool,
}

/// Ground polygons in the world frame, in drawing order (back to front within each kind).
pub(super) fn ground(road: &Road, ego: &VehicleView) -> Vec<GroundQuad> {
    let mut quads = Vec::with_capacity(256);
    let (ex, ey) = (ego.rear_axle.x, ego.rear_axle.y);
    let g = 2000.0;
    quads.push(GroundQuad {
        corners: [
            Point3::new(ex - g, ey - g, 0.0),
            Point3::new(ex + g, ey - g, 0.0),
            Point3::new(ex + g, ey + g, 0.0),
            Point3::new(ex - g, ey + g, 0.0),
        ],
        color: GRASS,
        smooth: false,
    });
    let at = |s: f64, d: f64| {
        let p = road.to_world(s, d);
        Point3::new(p.x, p.y, 0.0)
    };
    // Road surface in cross-sections, coarser with distance; far ones first.
    let mut sections = Vec::new();
    let mut s = ego.s_m - 20.0;
    while s < ego.s_m + ROAD_AHEAD_M {
        sections.push(s);
        s += if s < ego.s_m + 60.0 { 2.0 } else { 5.0 };
    }
    // The edges move in where an outer lane ends (over its taper).
    for pair in sections.windows(2).rev() {
        let (a, b) = (pair[0], pair[1]);
        let ((ra, la), (rb, lb)) = (road.edges_d(a), road.edges_d(b));
        quads.push(GroundQuad {
            corners: [at(a, ra - SHOULDER_M), at(b, rb - SHOULDER_M), at(b, lb + SHOULDER_M), at(a, la + SHOULDER_M)],
            color: ASPHALT,
            smooth: false,
        });
    }
    let line = |s0: f64, s1: f64, d0: f64, d1: f64| {
        let h = MARKING_WIDTH_M / 2.0;
        GroundQuad {
            corners: [at(s0, d0 - h), at(s1, d1 - h), at(s1, d1 + h), at(s0, d0 + h)],
            color: MARKING,
            smooth: true,
        }
    };
    let hw = road.half_width_m();
    // Solid edge lines.
    for pair in sections.windows(2).rev().filter(|p| p[0] < ego.s_m + MARKINGS_AHEAD_M) {
        let ((ra, la), (rb, lb)) = (road.edges_d(pair[0]), road.edges_d(pair[1]));
        quads.push(line(pair[0], pair[1], ra + MARKING_WIDTH_M, rb + MARKING_WIDTH_M));
        quads.push(line(pair[0], pair[1], la - MARKING_WIDTH_M, lb - MARKING_WIDTH_M));
    }
    // Dashed lane separators, fixed to the road.
    let first = ((ego.s_m - 20.0) / DASH_PERIOD_M).floor() as i64;
    let last = ((ego.s_m + MARKINGS_AHEAD_M) / DASH_PERIOD_M).ceil() as i64;
    for k in (first..=last).rev() {
        let s0 = k as f64 * DASH_PERIOD_M;
        for lane in 1..road.lanes() {
            // The line beside a lane that ends stops where its taper begins.
            let ending = [lane - 1, lane]
                .into_iter()
                .any(|l| road.lane_end(l).is_some_and(|e| s0 + DASH_M > e.end_m - e.taper_m));
            if ending {
                continue;
            }
            let d = -hw + lane as f64 * road.lane_width_m();
            quads.push(line(s0, s0 + DASH_M, d, d));
        }
    }
    quads
}

/// The dark patch under a vehicle, in the world frame.
pub(super) fn shadow(v: &VehicleView) -> [Point3<f64>; 4] {
    let p = &v.params;
    let (x0, x1) = (-p.rear_overhang_m - 0.1, p.size_m[0] - p.rear_overhang_m + 0.1);
    let y = p.size_m[1] / 2.0 + 0.1;
    let (sin, cos) = v.yaw_rad.sin_cos();
    [(x0, -y), (x1, -y), (x1, y), (x0, y)]
        .map(|(x, y)| Point3::new(v.rear_axle.x + x * cos - y * sin, v.rear_axle.y + x * sin + y * cos, 0.0))
}

/// One face of a vehicle's box, in its body frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Face {
    pub corners: [Point3<f64>; 4],
    pub normal: Vector3<f64>,
    pub color: [u8; 3],
    /// A lamp that is on: drawn in its own colour, not shaded.
    pub emissive: bool,
}

impl Face {
    /// Whether the face points toward a viewer at `eye` (body frame).
    pub(super) fn faces(&self, eye: &Point3<f64>) -> bool {
        (eye - self.corners[0]).dot(&self.normal) > 0.0
    }

    /// The colour lit by a fixed sun, for a body turned by `yaw_rad`.
    pub(super) fn shaded(&self, yaw_rad: f64) -> [u8; 3] {
        if self.emissive {
            return self.color;
        }
        let sun = Vector3::new(-0.35, 0.45, 0.82).normalize();
        let (sin, cos) = yaw_rad.sin_cos();
        let n = Vector3::new(
            self.normal.x * cos - self.normal.y * sin,
            self.normal.x * sin + self.normal.y * cos,
            self.normal.z,
        );
        let light = 0.55 + 0.45 * n.dot(&sun).max(0.0);
        self.color.map(|c| (c as f64 * light).round().min(255.0) as u8)
    }
}

/// Colours of a box's visible faces: front (+x), rear (-x), sides (+-y), top (+z).
struct BoxColors {
    front: [u8; 3],
    rear: [u8; 3],
    sides: [u8; 3],
    top: [u8; 3],
}

impl BoxColors {
    fn all(c: [u8; 3]) -> Self {
        BoxColors { front: c, rear: c, sides: c, top: c }
    }
}

/// The five faces (no bottom: the camera is never under a vehicle) of the box min..max.
fn cuboid(out: &mut Vec<Face>, min: [f64; 3], max: [f64; 3], colors: BoxColors) {
    let [x0, y0, z0] = min;
    let [x1, y1, z1] = max;
    let p = Point3::new;
    let mut face = |corners, normal: [f64; 3], color| {
        out.push(Face { corners, normal: Vector3::from(normal), color, emissive: false });
    };
    face([p(x1, y0, z0), p(x1, y1, z0), p(x1, y1, z1), p(x1, y0, z1)], [1.0, 0.0, 0.0], colors.front);
    face([p(x0, y1, z0), p(x0, y0, z0), p(x0, y0, z1), p(x0, y1, z1)], [-1.0, 0.0, 0.0], colors.rear);
    face([p(x0, y1, z0), p(x1, y1, z0), p(x1, y1, z1), p(x0, y1, z1)], [0.0, 1.0, 0.0], colors.sides);
    face([p(x1, y0, z0), p(x0, y0, z0), p(x0, y0, z1), p(x1, y0, z1)], [0.0, -1.0, 0.0], colors.sides);
    face([p(x0, y0, z1), p(x1, y0, z1), p(x1, y1, z1), p(x0, y1, z1)], [0.0, 0.0, 1.0], colors.top);
}

/// A vehicle as boxes: body, cabin (glass sides), wheels, tail lights; a truck gets a cargo box.
pub(super) fn vehicle_faces(v: &VehicleView) -> Vec<Face> {
    if v.class == ObjectClass::Motorcycle {
        return motorcycle_faces(v);
    }
    let p = &v.params;
    let [length, width, height] = p.size_m;
    let rear = -p.rear_overhang_m;
    let front = rear + length;
    let hw = width / 2.0;
    let body = v.color;
    let mut faces = Vec::with_capacity(48);
    match v.class {
        ObjectClass::Truck => {
            let cab_start = front - 2.3;
            cuboid(&mut faces, [rear, -hw, 0.45], [front, hw, 0.95], BoxColors::all(TRIM));
            cuboid(&mut faces, [rear, -hw, 0.95], [cab_start - 0.2, hw, height], BoxColors::all(body));
            cuboid(
                &mut faces,
                [cab_start, -hw, 0.95],
                [front, hw, height * 0.85],
                BoxColors { front: GLASS, rear: body, sides: body, top: body },
            );
        }
        ObjectClass::Van => {
            cuboid(&mut faces, [rear, -hw, 0.3], [front, hw, height * 0.5], BoxColors::all(body));
            cuboid(
                &mut faces,
                [rear, -hw * 0.97, height * 0.5],
                [front - 0.9, hw * 0.97, height],
                BoxColors { front: GLASS, rear: body, sides: body, top: body },
            );
        }
        // Motorcycles are drawn by `motorcycle_faces`.
        ObjectClass::Car | ObjectClass::Unknown | ObjectClass::Motorcycle => {
            let waist = height * 0.58;
            cuboid(&mut faces, [rear, -hw, 0.28], [front, hw, waist], BoxColors::all(body));
            cuboid(
                &mut faces,
                [rear + 0.2 * length, -hw * 0.88, waist],
                [rear + 0.74 * length, hw * 0.88, height],
                BoxColors { front: GLASS, rear: GLASS, sides: GLASS, top: body },
            );
        }
    }
    // Wheels at both axles, a little inside the body's sides.
    let r = 0.33;
    for x in [0.0, p.wheelbase_m] {
        for side in [-1.0, 1.0] {
            let (ya, yb) = (side * (hw - 0.3), side * (hw + 0.01));
            cuboid(&mut faces, [x - r, ya.min(yb), 0.0], [x + r, ya.max(yb), 2.0 * r], BoxColors::all(TYRE));
        }
    }
    // Tail lights on the rear face, lit when braking.
    let light_z = if v.class == ObjectClass::Truck { [0.55, 0.85] } else { [height * 0.42, height * 0.54] };
    for side in [-1.0, 1.0] {
        let (ya, yb) = (side * (hw - 0.45), side * (hw - 0.08));
        tail_light(
            &mut faces,
            v.brake_lights,
            [rear - 0.03, ya.min(yb), light_z[0]],
            [rear + 0.01, ya.max(yb), light_z[1]],
        );
    }
    faces
}

/// A tail light as a box; on (braking), it emits BRAKE_LIGHT.
fn tail_light(out: &mut Vec<Face>, on: bool, min: [f64; 3], max: [f64; 3]) {
    let from = out.len();
    cuboid(out, min, max, BoxColors::all(if on { BRAKE_LIGHT } else { TAIL_LIGHT }));
    for f in &mut out[from..] {
        f.emissive = on;
    }
}

/// A motorcycle and its rider as boxes: two wheels in line, the machine between them, the
/// rider's torso and helmet, one tail light.
fn motorcycle_faces(v: &VehicleView) -> Vec<Face> {
    let p = &v.params;
    let [length, _, height] = p.size_m;
    let rear = -p.rear_overhang_m;
    let front = rear + length;
    let mut faces = Vec::with_capacity(30);
    let r = 0.32;
    for x in [0.0, p.wheelbase_m] {
        cuboid(&mut faces, [x - r, -0.08, 0.0], [x + r, 0.08, 2.0 * r], BoxColors::all(TYRE));
    }
    cuboid(&mut faces, [rear + 0.15, -0.22, 0.3], [front - 0.3, 0.22, 0.85], BoxColors::all(v.color));
    cuboid(&mut faces, [0.2, -0.25, 0.85], [0.75, 0.25, height - 0.28], BoxColors::all(RIDER));
    cuboid(&mut faces, [0.33, -0.14, height - 0.28], [0.63, 0.14, height], BoxColors::all(v.color));
    tail_light(&mut faces, v.brake_lights, [rear - 0.03, -0.1, 0.68], [rear + 0.01, 0.1, 0.8]);
    faces
}
