//! Finds vehicles in one RGB frame with classical computer vision and the camera geometry.
//!
//! The method (docs/perception.md):
//! 1. Luminance; the road's brightness is the mode of the lower image (the road fills it).
//! 2. The dark band where a vehicle meets the road (its shadow, tyres and underbody) is much
//!    darker than the road in any colour, brightness or noise: pixels below `dark_ratio` of
//!    the road's brightness, below the horizon, grouped into connected components.
//! 3. A component's lowest row is the contact line, located to a fraction of a row from how
//!    much of the band the pixels on its edge hold: its ground distance comes from the ray
//!    through it (flat road), which gives the metres-per-pixel scale there. A band wider than a
//!    rear whose edge rises toward one end is a rear and a side (a vehicle turned from the line
//!    of sight, in a bend): placed by the rear's outer edge.
//! 4. Above the contact line, the rows whose pixels differ from the background on both sides
//!    (road or sky, sampled just outside the component) give the vehicle's height; a band too
//!    narrow or too low for a vehicle at that distance is rejected.
//! 5. A candidate lying inside the box of a nearer one (a dark window, a black car's body) is
//!    part of it and suppressed.
//! 6. Brake lights: lit lamps are a saturated red brighter than any sunlit paint (red near
//!    full scale, green and blue far below it); such pixels low in the vehicle's box, on both
//!    sides of its middle (a motorcycle: anywhere), mean its brake lights are on.
//!
//! It reads only pixels and the camera info: no ground truth, no palette.

use super::geometry::CameraModel;
use crate::msg::{BoundingBox2d, CameraInfo, ObjectClass};
use crate::vehicle::VehicleParams;

/// Tunable thresholds (the defaults are what docs/perception.md measures).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DetectorParams {
    /// A pixel is "contact-dark" below this share of the road's luminance.
    pub dark_ratio: f32,
    /// Plausible widths of the dark contact band, metres (a partly hidden vehicle shows less).
    pub min_width_m: f64,
    pub max_width_m: f64,
    /// Plausible heights, metres.
    pub min_height_m: f64,
    pub max_height_m: f64,
    /// Colour difference (sum over RGB) that separates a vehicle from its background.
    pub contrast: i32,
    /// Farthest distance reported.
    pub max_distance_m: f64,
    /// The contact band's luminance as a share of the road's until a vehicle near enough to
    /// measure it is seen (a daylight contact shadow is about half as bright as the road).
    pub band_ratio: f32,
}

impl Default for DetectorParams {
    fn default() -> Self {
        DetectorParams {
            dark_ratio: 0.78,
            min_width_m: 0.6,
            max_width_m: 3.6,
            min_height_m: 0.7,
            max_height_m: 4.5,
            contrast: 24,
            max_distance_m: 80.0,
            band_ratio: 0.5,
        }
    }
}

/// One vehicle found in one frame (before tracking).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameDetection {
    pub bbox: BoundingBox2d,
    pub class: ObjectClass,
    /// Ego body x of the vehicle's rear (its contact line).
    pub distance_m: f64,
    /// The distance's expected error (one standard deviation), from the ground one row
    /// covers there through this camera.
    pub distance_sigma_m: f64,
    /// Ego body y of its centre.
    pub lateral_offset_m: f64,
    pub height_m: f64,
    pub width_m: f64,
    pub confidence: f32,
    /// Its brake lights are lit in this frame.
    pub brake_lights: bool,
}

/// A lit lamp's pixel: red at least this, and this much above green and above blue. A tail
/// light that is off, or a red body in sunlight, stays below (the brightest sunlit face of a
/// pure red body has its red only at full scale with green and blue near 0: such a body would
/// read as braking; no scenario colour comes near).
const LIT_RED_MIN: u8 = 235;
const LIT_RED_OVER_GB: i32 = 150;
/// Lit pixels in a motorcycle's box that mean its brake light is on (other vehicles need one on
/// each side; a lamp 150 m ahead covers ~8 pixels in the narrow camera, 50 m ahead ~6 in the
/// front one).
const LIT_LAMP_MIN_PX: u32 = 2;

/// Stop lamps are looked for up to this height above the ground (regulations put them between
/// about 0.35 and 1.5 m; the simulator's cars have theirs at 0.6-0.8 m, vans' to 1.2 m).
const LAMPS_MAX_HEIGHT_M: f64 = 1.3;

/// Background beside a band is sampled this many columns outside it.
const FLANK_PX: usize = 3;

/// Largest step of the contact row between neighbouring columns of one vehicle, pixels.
const JUMP_PX: i64 = 3;

/// A contact shadow is lit by the sky: never darker than this share of the sunlit road
/// (anything darker measured in the band is a tyre or a black body, not ground).
const MIN_BAND_RATIO: f32 = 0.3;

/// The contact shadow reaches this far behind a vehicle's rear, so the rear stands this much
/// beyond the contact line. Calibrated with `slipstream eval detect`: without it every range
/// from 5 to 40 m was short by 0.09-0.10 m (1.1% at 7 m), which at 5 m/s is 0.02 s of time gap.
const SHADOW_BEHIND_REAR_M: f64 = 0.1;

/// How far one frame's measurement of the band's brightness moves the detector's estimate.
const BAND_RATIO_GAIN: f32 = 0.05;

/// How well the contact edge is located, rows (docs/perception.md: range errors within 0.1%
/// (p90) to 60 m through the front camera).
const EDGE_SIGMA_ROWS: f64 = 0.06;
const DISTANCE_SIGMA_FLOOR_M: f64 = 0.05;

/// A contact band narrower than this (and seen whole) is a motorcycle's: cars are 1.6 m wide
/// and more.
const MOTORCYCLE_MAX_WIDTH_M: f64 = 1.2;

/// Pixels between two dark components on one row darker than this share of the road's
/// luminance (on average) are the thin band of one vehicle joining its wheels.
const BRIDGE_RATIO: f32 = 0.9;

/// The most road a vehicle's body shows beneath it between its wheels, metres (a truck's rear
/// under-ride bar; a car's is 0.2-0.3 m).
const GROUND_CLEARANCE_M: f64 = 1.0;

/// A dark region this many times as tall as the band beside it is something else.
const TALL_RATIO: u32 = 4;

/// Rows within which a contact profile counts as flat.
const FLAT_PX: u32 = 2;

/// The widest band taken for a vehicle seen from behind and from one side (in a bend, or
/// turning): a truck 9.5 m long turned 38 degrees from the line of sight shows this much.
const MAX_OBLIQUE_WIDTH_M: f64 = 8.0;

/// The widest band taken for one vehicle when its contact line does not show which side
/// recedes (far away a side 10 m deep rises a row or two): a truck turned 15 degrees.
const MAX_LEVEL_OBLIQUE_WIDTH_M: f64 = 5.0;

/// How far a vehicle's body can reach beyond its wheels to the side, metres.
const MAX_OVERHANG_M: f64 = 0.6;

/// A band wider than this is more than a rear (a truck's 2.5 m and its shadow's margins):
/// whether a side recedes beside it is looked for.
const MAX_REAR_WIDTH_M: f64 = 2.9;

/// Rows by which a band's contact edge must rise toward one end, over its outer quarter, more
/// than toward the other, for that end to be a vehicle's side receding from its rear (a
/// truck's side 150 m ahead, turned 10 degrees, rises about one row).
const SIDE_RISE_PX: f64 = 0.3;

/// Which way a vehicle's side, seen beside its rear, lies in the image.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Side {
    Left,
    Right,
}

/// A run of dark pixels on one row, and the component it belongs to.
#[derive(Debug, Clone, Copy)]
struct Run {
    row: u32,
    u0: u32,
    u1: u32,
}

/// A stretch of columns of one dark component whose contact row is continuous.
#[derive(Debug, Clone, Copy)]
struct Component {
    u0: u32,
    u1: u32,
    /// Lowest row (largest v).
    v1: u32,
    /// Columns whose contact row is within FLAT_PX of the lowest.
    flat_u0: u32,
    flat_u1: u32,
    /// The columns of the dark region it is part of that join it without a gap, where their
    /// contact row is no lower than its own (u0..=u1 at least).
    reach_u0: u32,
    reach_u1: u32,
}

/// Reusable detector for one camera.
pub struct Detector {
    camera: CameraModel,
    params: DetectorParams,
    horizon_v: f64,
    luma: Vec<u8>,
    /// The frame smoothed, when it is noisy.
    smooth: Vec<u8>,
    runs: Vec<Run>,
    parent: Vec<u32>,
    /// This frame's contact-dark threshold.
    dark: u8,
    /// The contact band's luminance as a share of the road's: measured on every vehicle near
    /// enough for its band to hold whole pixels, kept for frames without one.
    band_ratio: f32,
}

impl Detector {
    pub fn new(info: &CameraInfo, params: DetectorParams) -> Detector {
        let camera = CameraModel::new(info);
        let horizon_v = camera.horizon_v();
        Detector {
            camera,
            params,
            horizon_v,
            luma: Vec::new(),
            smooth: Vec::new(),
            runs: Vec::new(),
            parent: Vec::new(),
            dark: 0,
            band_ratio: params.band_ratio,
        }
    }

    pub fn camera(&self) -> &CameraModel {
        &self.camera
    }

    /// Vehicles in an RGB8 frame of the camera's size.
    pub fn detect(&mut self, rgb: &[u8]) -> Vec<FrameDetection> {
        let (w, h) = (self.camera.info.width as usize, self.camera.info.height as usize);
        if rgb.len() != w * h * 3 {
            return Vec::new();
        }
        let first_ground_row = (self.horizon_v.ceil().max(0.0) as usize + 1).min(h);
        if first_ground_row + 4 >= h {
            return Vec::new();
        }
        self.to_luma(rgb);
        // A noisy sensor (low light, high gain): the frame is smoothed along its rows first,
        // which leaves the contact row (the range) where it is. Only then: the copy and the
        // luma again cost about 2 ms a frame for both cameras (docs/perception.md).
        if luma_noise(&self.luma, w, h, first_ground_row) > SMOOTH_ABOVE_NOISE {
            let mut smooth = std::mem::take(&mut self.smooth);
            smooth_rows(rgb, &mut smooth, w);
            self.to_luma(&smooth);
            let found = self.detect_in(&smooth, first_ground_row);
            self.smooth = smooth;
            return found;
        }
        self.detect_in(rgb, first_ground_row)
    }

    /// The luma of an RGB8 frame.
    fn to_luma(&mut self, rgb: &[u8]) {
        self.luma.resize(rgb.len() / 3, 0);
        // Weights summing to 256 in 16 bits: the loop vectorises.
        for (y, p) in self.luma.iter_mut().zip(rgb.chunks_exact(3)) {
            *y = ((77 * p[0] as u16 + 150 * p[1] as u16 + 29 * p[2] as u16) >> 8) as u8;
        }
    }

    /// [`Detector::detect`] on a frame whose luma is computed, below `first_ground_row`.
    fn detect_in(&mut self, rgb: &[u8], first_ground_row: usize) -> Vec<FrameDetection> {
        let (w, h) = (self.camera.info.width as usize, self.camera.info.height as usize);
        let road = road_luma(&self.luma, w, h, first_ground_row);
        let dark = (road as f32 * self.params.dark_ratio) as u8;
        self.dark = dark;
        let components = self.dark_components(w, h, first_ground_row, dark);
        let components = self.join_split_bands(w, road, components);
        if tracing::enabled!(tracing::Level::TRACE) {
            tracing::trace!(road, dark, first_ground_row, runs = self.runs.len(), "frame");
            for c in &components {
                tracing::trace!(?c, verdict = ?self.candidate(rgb, w, h, c), "contact band");
            }
        }

        let mut kept = self.vehicles(rgb, w, h, &components);
        // The band's brightness, measured on the vehicles found where their band is thick
        // enough; when it moved, their distances are measured again with it.
        let mut ratios: Vec<f32> = kept.iter().filter_map(|(i, _)| self.band_ratio_of(w, h, &components[*i])).collect();
        if !ratios.is_empty() {
            ratios.sort_by(f32::total_cmp);
            // Lighting changes slowly; one frame's measurement (a tyre or a partly covered
            // pixel in it) must not move every other vehicle's range: a slow average.
            let measured = ratios[ratios.len() / 2].clamp(MIN_BAND_RATIO, self.params.dark_ratio);
            let ratio = self.band_ratio + BAND_RATIO_GAIN * (measured - self.band_ratio);
            if ratio != self.band_ratio {
                self.band_ratio = ratio;
                kept = self.vehicles(rgb, w, h, &components);
            }
        }
        kept.into_iter().map(|(_, d)| d).collect()
    }

    /// The components that pass as vehicles (with their index), nearest first, those inside a
    /// nearer one's box left out (a dark window, a black car's body).
    fn vehicles(&self, rgb: &[u8], w: usize, h: usize, components: &[Component]) -> Vec<(usize, FrameDetection)> {
        let mut candidates: Vec<(usize, FrameDetection)> =
            components.iter().enumerate().filter_map(|(i, c)| Some((i, self.candidate(rgb, w, h, c).ok()?))).collect();
        candidates.sort_by(|a, b| b.1.bbox.v_max_px.total_cmp(&a.1.bbox.v_max_px));
        let mut kept: Vec<(usize, FrameDetection)> = Vec::new();
        for (i, c) in candidates {
            let inside = kept.iter().any(|(_, k)| part_of(&c.bbox, &k.bbox));
            if !inside {
                kept.push((i, c));
            }
        }
        kept
    }

    /// Connected components of the pixels darker than `dark`, below the horizon.
    fn dark_components(&mut self, w: usize, h: usize, first_row: usize, dark: u8) -> Vec<Component> {
        let row_start = self.dark_runs(w, h, first_row, dark);
        self.join_runs(&row_start);
        let (kept, cols) = self.contact_profiles();
        let mut out = Vec::new();
        let mut merged: Vec<(u32, u32, u32)> = Vec::new();
        for (k, &(_, first, offset)) in kept.iter().enumerate() {
            let end = kept.get(k + 1).map_or(cols.len(), |c| c.2);
            // (column, lowest row, highest row) per column.
            merged.clear();
            merged.extend(
                cols[offset..end]
                    .iter()
                    .enumerate()
                    .filter(|(_, c)| c.1 != u32::MAX)
                    .map(|(j, &(lo, hi))| (first + j as u32, lo, hi)),
            );
            split_profile(&merged, &mut out);
        }
        out
    }

    /// The horizontal runs of dark pixels, row by row from `first_row`, into `self.runs`;
    /// returns where each row's runs start (and, last, their count).
    fn dark_runs(&mut self, w: usize, h: usize, first_row: usize, dark: u8) -> Vec<usize> {
        self.runs.clear();
        let mut row_start = Vec::with_capacity(h - first_row + 1);
        for v in first_row..h {
            row_start.push(self.runs.len());
            let row = &self.luma[v * w..(v + 1) * w];
            let mut u = 0;
            while u < w {
                if row[u] < dark {
                    let start = u;
                    while u < w && row[u] < dark {
                        u += 1;
                    }
                    self.runs.push(Run { row: v as u32, u0: start as u32, u1: u as u32 - 1 });
                } else {
                    u += 1;
                }
            }
        }
        row_start.push(self.runs.len());
        row_start
    }

    /// Joins runs that touch runs of the row above (4-connected) in `self.parent`.
    fn join_runs(&mut self, row_start: &[usize]) {
        self.parent.clear();
        self.parent.extend(0..self.runs.len() as u32);
        for r in 1..row_start.len() - 1 {
            let (above, here) = (row_start[r - 1]..row_start[r], row_start[r]..row_start[r + 1]);
            let mut a = above.start;
            for i in here {
                let run = self.runs[i];
                while a < above.end && self.runs[a].u1 < run.u0 {
                    a += 1;
                }
                let mut b = a;
                while b < above.end && self.runs[b].u0 <= run.u1 {
                    union(&mut self.parent, i as u32, b as u32);
                    b += 1;
                }
            }
        }
    }

    /// Per component of at least three pixels, the lowest and the highest dark row of each
    /// column it covers: the contact profile. Returns the components in root order as (root,
    /// first column, offset of its columns) and the columns of all of them in one buffer
    /// ((0, u32::MAX) where a component has no pixel): one pass over the runs, no per-pixel
    /// allocation or sort.
    #[allow(clippy::type_complexity)]
    fn contact_profiles(&mut self) -> (Vec<(u32, u32, usize)>, Vec<(u32, u32)>) {
        let mut roots = Vec::with_capacity(self.runs.len());
        let mut extent: std::collections::HashMap<u32, (u32, u32, u32)> = std::collections::HashMap::new();
        for i in 0..self.runs.len() {
            let root = find(&mut self.parent, i as u32);
            roots.push(root);
            let r = self.runs[i];
            let e = extent.entry(root).or_insert((r.u0, r.u1, 0));
            e.0 = e.0.min(r.u0);
            e.1 = e.1.max(r.u1);
            e.2 += r.u1 - r.u0 + 1;
        }
        let mut kept: Vec<(u32, u32, u32)> =
            extent.iter().filter(|e| e.1 .2 >= 3).map(|(&r, e)| (r, e.0, e.1)).collect();
        kept.sort_unstable();
        let mut len = 0;
        let kept: Vec<(u32, u32, usize)> = kept
            .into_iter()
            .map(|(root, u0, u1)| {
                let offset = len;
                len += (u1 - u0 + 1) as usize;
                (root, u0, offset)
            })
            .collect();
        const NONE: (u32, u32) = (0, u32::MAX);
        let mut cols = vec![NONE; len];
        for (r, root) in self.runs.iter().zip(&roots) {
            let Ok(k) = kept.binary_search_by_key(root, |c| c.0) else { continue };
            let (_, first, offset) = kept[k];
            for c in &mut cols[offset + (r.u0 - first) as usize..=offset + (r.u1 - first) as usize] {
                c.0 = c.0.max(r.row);
                c.1 = c.1.min(r.row);
            }
        }
        (kept, cols)
    }

    /// Far away the band under a vehicle is thinner than a row: blended with the road, it is
    /// no longer darker than the threshold, and only the wheels at its sides are. Two
    /// components on the same contact row are one vehicle's when the pixels between them on
    /// that row are darker than the road (the thin band), or on a row above it within a
    /// vehicle's ground clearance (the band fell between rows and the road under the body
    /// shows between the wheels), and together they are no wider than a vehicle at their
    /// distance (two vehicles side by side are a lane apart: wider).
    fn join_split_bands(&self, w: usize, road: u8, mut components: Vec<Component>) -> Vec<Component> {
        let origin_x = self.camera.origin_in_body().x;
        let bridge = road as f32 * BRIDGE_RATIO;
        components.sort_by_key(|c| c.u0);
        let mut i = 0;
        while i < components.len() {
            let a = components[i];
            let partner = components.iter().enumerate().skip(i + 1).find_map(|(j, b)| {
                if b.u0 <= a.u1 + 1 || b.v1.abs_diff(a.v1) > 1 {
                    return None;
                }
                let v1 = a.v1.max(b.v1);
                let contact = self.camera.ground_point((a.u0 + b.u1 + 1) as f64 / 2.0, v1 as f64 + 1.0)?;
                let px_per_m = self.camera.info.fx_px / (contact.x - origin_x).max(0.5);
                if (b.u1 + 1 - a.u0) as f64 / px_per_m > self.params.max_width_m {
                    return None;
                }
                let between = |v: u32| {
                    let row = &self.luma[v as usize * w..(v as usize + 1) * w];
                    let gap = &row[a.u1 as usize + 1..b.u0 as usize];
                    gap.iter().map(|&l| l as f32).sum::<f32>() / gap.len() as f32
                };
                let clearance_rows = (GROUND_CLEARANCE_M * px_per_m).ceil() as u32 + 1;
                let darkest = (0..=clearance_rows.min(v1)).map(|up| between(v1 - up)).fold(f32::INFINITY, f32::min);
                (darkest < bridge).then_some(j)
            });
            match partner {
                Some(j) => {
                    let b = components.remove(j);
                    components[i] = Component {
                        u0: a.u0,
                        u1: b.u1,
                        v1: a.v1.max(b.v1),
                        flat_u0: a.flat_u0.min(b.flat_u0),
                        flat_u1: a.flat_u1.max(b.flat_u1),
                        reach_u0: a.reach_u0.min(b.reach_u0),
                        reach_u1: a.reach_u1.max(b.reach_u1),
                    };
                    // The joined band may join the next one too: look again from it.
                }
                None => i += 1,
            }
        }
        components
    }

    /// Checks a dark component as a vehicle's contact band and measures the vehicle above it.
    fn candidate(&self, rgb: &[u8], w: usize, h: usize, c: &Component) -> Result<FrameDetection, String> {
        let p = &self.params;
        // The contact line is the lower edge of the component's lowest row; its horizontal
        // extent is that of the component's bottom rows.
        let contact_v = c.v1 as f64 + 1.0;
        if c.v1 as usize >= h - 1 {
            return Err("runs off the image bottom: the contact line is not seen".into());
        }
        let (bu0, bu1) = (c.flat_u0, c.flat_u1);
        let centre_u = (bu0 + bu1 + 1) as f64 / 2.0;
        let edge_v = self.contact_edge(w, h, c).unwrap_or(contact_v);
        let contact = self.camera.ground_point(centre_u, edge_v).ok_or("contact above the horizon")?;
        if contact.x < 1.0 || contact.x > p.max_distance_m {
            return Err(format!("contact at {:.1} m", contact.x));
        }
        let origin = self.camera.origin_in_body();
        let px_per_m = self.camera.info.fx_px / (contact.x - origin.x).max(0.5);
        let width_m = (bu1 - bu0 + 1) as f64 / px_per_m;
        let (u0, u1) = (c.u0.min(bu0) as usize, c.u1.max(bu1) as usize);
        let oblique = self.oblique_side(w, h, c, width_m)?;
        let (top, height_m, (r0, r1)) = self.height(rgb, w, c, (u0, u1), contact_v, px_per_m)?;
        // Not cut by the image's side.
        let whole = bu0 > 0 && (bu1 as usize) + 1 < w;
        let class = class_of(width_m, height_m, whole);
        let confidence = confidence_of(class, width_m, height_m);
        // A vehicle cut by the image's side (one being passed): the band's centre is the visible
        // part's, metres inside the vehicle's own, which would put a car of the next lane into
        // the ego's. Its inner side is measured: the centre lies half its class's width beyond.
        let half_width = VehicleParams::of_class(class).size_m[1] / 2.0;
        // Seen obliquely, the rear's outer edge is the band's end away from the side.
        let lateral_offset_m = match (bu0 == 0, bu1 as usize + 1 >= w, oblique) {
            (true, false, _) => self.camera.lateral_at((bu1 + 1) as f64, edge_v, contact.x) + half_width,
            (false, true, _) => self.camera.lateral_at(bu0 as f64, edge_v, contact.x) - half_width,
            (_, _, Some(Side::Left)) => self.camera.lateral_at((r1 + 1) as f64, edge_v, contact.x) + half_width,
            (_, _, Some(Side::Right)) => self.camera.lateral_at(r0 as f64, edge_v, contact.x) - half_width,
            _ => contact.y,
        };
        // Stop lamps sit at most LAMPS_MAX_HEIGHT_M above the ground, one on each side (a
        // motorcycle's single lamp in the middle): a lamp of a vehicle beside or beyond this
        // one, showing at one edge of its box, does not light it.
        let lamps_top = (contact_v - LAMPS_MAX_HEIGHT_M * px_per_m).floor().max(top as f64) as usize;
        let rows = lamps_top..=c.v1 as usize;
        // Cut by the image's side, the other lamp may be out of view.
        let brake_lights = if class == ObjectClass::Motorcycle || !whole {
            lit_pixels(rgb, w, u0..=u1, rows) >= LIT_LAMP_MIN_PX
        } else {
            // Seen from the side as well, the lamps are either side of the rear's middle.
            let rear_half_px = (half_width * px_per_m) as usize;
            let mid = match oblique {
                Some(Side::Right) => (r0 + rear_half_px).min(u1 - 1).max(u0),
                Some(Side::Left) => (r1 + 1).saturating_sub(rear_half_px).min(u1 - 1).max(u0),
                None => (u0 + u1) / 2,
            };
            lit_pixels(rgb, w, u0..=mid, rows.clone()) >= 1 && lit_pixels(rgb, w, mid + 1..=u1, rows) >= 1
        };
        Ok(FrameDetection {
            bbox: BoundingBox2d {
                u_min_px: u0 as f32,
                v_min_px: top as f32,
                u_max_px: (u1 + 1) as f32,
                v_max_px: contact_v as f32,
            },
            class,
            distance_m: contact.x + SHADOW_BEHIND_REAR_M,
            distance_sigma_m: self.distance_sigma_m(contact.x),
            lateral_offset_m,
            height_m,
            width_m,
            confidence,
            brake_lights,
        })
    }

    /// The vehicle's top row and height above the contact line at `contact_v`, over the columns
    /// `u0..=u1`, measured against the background beside them; and the columns its body may
    /// reach beyond the band (r0, r1). The background just beside the band can be the
    /// vehicle's own body where it overhangs its wheels (a truck's bumper, seen when the shadow
    /// under it is too thin to show): where dark columns of the same region adjoin the band,
    /// the height is measured beside them (as far as a body overhangs), and beside the band
    /// only if that fails; last, beside the widest overhang a body can have (a van's box over
    /// its wheels, with no dark chassis under it to show where it ends).
    fn height(
        &self,
        rgb: &[u8],
        w: usize,
        c: &Component,
        (u0, u1): (usize, usize),
        contact_v: f64,
        px_per_m: f64,
    ) -> Result<(usize, f64, (usize, usize)), String> {
        let p = &self.params;
        let max_rows = (p.max_height_m * px_per_m) as usize;
        // The background columns just outside a0..=a1, where the image has them.
        let beside = |a0: usize, a1: usize| [a0.checked_sub(FLANK_PX), (a1 + FLANK_PX < w).then_some(a1 + FLANK_PX)];
        let flanks = beside(u0, u1);
        let height_from = |flanks: [Option<usize>; 2]| -> Result<(usize, f64), String> {
            let top = self
                .top_row(rgb, w, (u0, u1), (c.v1 as usize, max_rows), flanks)
                .ok_or("nothing rises above the contact")?;
            let height_m = (contact_v - top as f64) / px_per_m;
            if height_m < p.min_height_m || height_m > p.max_height_m {
                return Err(format!("height {height_m:.2} m"));
            }
            Ok((top, height_m))
        };
        let overhang_px = (MAX_OVERHANG_M * px_per_m).ceil() as u32;
        let (r0, r1) = (
            c.reach_u0.max((u0 as u32).saturating_sub(overhang_px)) as usize,
            c.reach_u1.min(u1 as u32 + overhang_px) as usize,
        );
        let outside_body = beside(r0, r1);
        let beyond_overhang = match u0.checked_sub(overhang_px as usize) {
            Some(o0) => beside(o0, u1 + overhang_px as usize),
            // The image's side is within the overhang: no background on that side.
            None => [None, beside(0, u1 + overhang_px as usize)[1]],
        };
        let (top, height_m) = if (r0, r1) != (u0, u1) {
            height_from(outside_body).or_else(|_| height_from(flanks))
        } else {
            height_from(flanks)
        }
        .or_else(|why| height_from(beyond_overhang).map_err(|_| why))?;
        Ok((top, height_m, (r0, r1)))
    }

    /// Seen from behind, the band is the rear's. A vehicle turned from the line of sight (in a
    /// bend) also shows one side, receding beside its rear: the band is wider than any rear,
    /// and the vehicle is placed by its rear's outer edge. Returns that side, None for a rear
    /// (or one whose side is too level to show: placed by the band's centre, off by at most
    /// half the side's width), or why a band of `width_m` is no vehicle.
    fn oblique_side(&self, w: usize, h: usize, c: &Component, width_m: f64) -> Result<Option<Side>, String> {
        let p = &self.params;
        if width_m < p.min_width_m {
            return Err(format!("width {width_m:.2} m"));
        }
        let side = if width_m > MAX_REAR_WIDTH_M { self.receding_side(w, h, c) } else { None };
        if side.is_some() && width_m <= MAX_OBLIQUE_WIDTH_M {
            Ok(side)
        } else if width_m <= p.max_width_m.max(MAX_LEVEL_OBLIQUE_WIDTH_M) {
            Ok(None)
        } else {
            Err(format!("width {width_m:.2} m"))
        }
    }

    /// A contact distance's expected error: the edge is located to about EDGE_SIGMA_ROWS of a
    /// row, and a row covers d^2 / (f h) metres of ground at distance d (f the focal length,
    /// h the camera's height), plus a floor for the ground model.
    fn distance_sigma_m(&self, d: f64) -> f64 {
        let o = self.camera.origin_in_body();
        let per_row = (d - o.x).max(0.5).powi(2) / (self.camera.info.fy_px * o.z.max(0.1));
        DISTANCE_SIGMA_FLOOR_M + EDGE_SIGMA_ROWS * per_row
    }

    /// The rear edge's columns (its end columns left out: they hold background too) with the
    /// lowest dark row of each, where that row is the edge's lowest or one above: far away the
    /// shadow under a vehicle is thinner than a row and can fall between rows, and then the
    /// columns between the wheels see the road under the body and end rows higher, at the
    /// body's lower edge (at 150 m three rows are 25 m).
    fn edge_columns(&self, w: usize, h: usize, c: &Component) -> Vec<(usize, usize)> {
        let (u0, u1) = if c.flat_u1 >= c.flat_u0 + 3 { (c.flat_u0 + 1, c.flat_u1 - 1) } else { (c.flat_u0, c.flat_u1) };
        let columns = self.lowest_dark_rows(w, h, u0..=u1, c.v1, FLAT_PX + 1);
        let lowest = columns.iter().map(|&(_, lo)| lo).max().unwrap_or(0);
        columns.into_iter().filter(|&(_, lo)| lo + 1 >= lowest).collect()
    }

    /// (column, lowest dark row) for the columns given, looking from `bottom` up to `rows`
    /// above it; columns without a dark pixel there, or too near the image's bottom for the
    /// road below to be measured, are left out.
    fn lowest_dark_rows(
        &self,
        w: usize,
        h: usize,
        columns: std::ops::RangeInclusive<u32>,
        bottom: u32,
        rows: u32,
    ) -> Vec<(usize, usize)> {
        let (top, bottom) = (bottom.saturating_sub(rows) as usize, (bottom as usize).min(h - 1));
        columns
            .filter_map(|u| {
                let u = u as usize;
                (top..=bottom).rev().find(|&v| self.luma[v * w + u] < self.dark).map(|lo| (u, lo))
            })
            .filter(|&(_, lo)| lo + 3 < h)
            .collect()
    }

    /// The road's luminance just below a contact edge (the median of the two rows under it).
    fn road_below(&self, w: usize, columns: &[(usize, usize)]) -> Option<f32> {
        median(columns.iter().flat_map(|&(u, lo)| [self.luma[(lo + 2) * w + u], self.luma[(lo + 3) * w + u]]).collect())
    }

    /// The band's luminance as a share of the road's, where the band is thick enough to hold
    /// whole pixels (four dark rows up from the edge): the median of the third.
    fn band_ratio_of(&self, w: usize, h: usize, c: &Component) -> Option<f32> {
        let columns = self.edge_columns(w, h, c);
        let dark = |u: usize, v: usize| self.luma[v * w + u] < self.dark;
        // The middle half of the rear edge: the tyres, darker than any shadow, stand at its
        // sides (seen from behind or, for a vehicle in the next lane, a little from the side).
        let quarter = columns.len() / 4;
        let inside: Vec<u8> = columns[quarter..columns.len() - quarter]
            .iter()
            .filter(|&&(u, lo)| lo >= 3 && dark(u, lo - 1) && dark(u, lo - 2) && dark(u, lo - 3))
            .map(|&(u, lo)| self.luma[(lo - 2) * w + u])
            .collect();
        if inside.len() < 5 || inside.len() * 4 < columns.len() {
            return None;
        }
        Some(median(inside)? / self.road_below(w, &columns)?.max(1.0))
    }

    /// Where the contact band's lower edge lies, to a fraction of a row (None when it cannot
    /// be measured). A camera's pixel on that edge holds band and road by the share of it each
    /// covers, share = (road - luma) / (road - band) within 0..1, so in each column of the rear
    /// edge the edge lies that share into the lowest row holding band: the road's luminance
    /// measured just below, the band's from the frame's band ratio
    /// (a band a pixel or two thick at 50 m holds no whole pixel to measure it by). Averaged
    /// over the columns, pixel noise mostly cancels.
    fn contact_edge(&self, w: usize, h: usize, c: &Component) -> Option<f64> {
        let columns = self.edge_columns(w, h, c);
        let (sum, n) = self.fractional_edges(w, &columns, true)?.fold((0.0, 0), |(s, n), e| (s + e, n + 1));
        Some(sum / n as f64)
    }

    /// The contact edge in the given columns (column, lowest row holding band), to a fraction
    /// of a row (`contact_edge`); None when it cannot be measured. With `skip_tyres`, columns
    /// whose lowest row is darker than any shadow are left out: they end on a tyre, whose
    /// lower edge says nothing of the band's within the row (it stays at the row's end, then
    /// jumps a row; a motorcycle's rear tyre stands at its rear, 0.13 m ahead of the band's
    /// edge, a car's far ones in its row from ~80 m). Only while a quarter of the columns hold
    /// band filling their lowest row's top and reaching as low as the tyres: far away the band
    /// is thinner than a row or falls between rows, and then the tyres' lower edge is the
    /// better measure. A side's rise (`receding_side`) keeps them: its quarters are the band's
    /// ends, where the tyres stand.
    fn fractional_edges<'a>(
        &'a self,
        w: usize,
        columns: &'a [(usize, usize)],
        skip_tyres: bool,
    ) -> Option<impl Iterator<Item = f64> + 'a> {
        let road = self.road_below(w, columns)?;
        let band = road * self.band_ratio;
        if road - band < 8.0 {
            return None;
        }
        let luma = move |u: usize, v: usize| self.luma[v * w + u];
        let share = move |l: u8| ((road - l as f32) / (road - band)).clamp(0.0, 1.0) as f64;
        let darkest_band = road * MIN_BAND_RATIO;
        let not_tyre = move |l: u8| l as f32 >= darkest_band;
        let on_band = move |&&(u, lo): &&(usize, usize)| not_tyre(luma(u, lo));
        // Band filling its lowest row's top (the row above holds band too, not a tyre, a
        // quarter of it at least, well above pixel noise): the share there is the edge's
        // place, not the band's thickness.
        let thick = |u: usize, lo: usize| lo > 0 && not_tyre(luma(u, lo - 1)) && share(luma(u, lo - 1)) >= 0.25;
        let tyres_left_out = skip_tyres && {
            let (mut banded, mut band_lowest, mut tyre_lowest) = (0, 0, 0);
            for c in columns {
                if !on_band(&c) {
                    tyre_lowest = tyre_lowest.max(c.1);
                } else if thick(c.0, c.1) {
                    (banded, band_lowest) = (banded + 1, band_lowest.max(c.1));
                }
            }
            banded > 0 && banded * 4 >= columns.len() && band_lowest >= tyre_lowest
        };
        let edge = move |u: usize, lo: usize| {
            let (inner, below) = (share(luma(u, lo)), share(luma(u, lo + 1)));
            // With band in the row below, the edge is in that row, whatever the band's top does
            // in row `lo` (at 50 m the band is hardly more than a row thick); with none there,
            // in row `lo`. Blended across a quarter of a row so that noise makes no step.
            let weight = (below / 0.25).min(1.0);
            weight * (lo as f64 + 1.0 + below) + (1.0 - weight) * (lo as f64 + inner + below)
        };
        Some(columns.iter().filter(move |c| !tyres_left_out || on_band(c)).map(move |&(u, lo)| edge(u, lo)))
    }

    /// Which end of a band its contact edge rises toward, measured to a fraction of a row over
    /// its outer quarters: a vehicle's side receding beside its rear (the rear's lower edge is
    /// level across the road; the side's runs away from the camera). None when neither end
    /// rises by SIDE_RISE_PX more than the other.
    fn receding_side(&self, w: usize, h: usize, c: &Component) -> Option<Side> {
        let columns = self.lowest_dark_rows(w, h, c.u0..=c.u1, c.v1, JUMP_PX as u32 + 1);
        if columns.len() < 8 {
            return None;
        }
        let edges: Vec<f64> = self.fractional_edges(w, &columns, false)?.collect();
        let quarter = edges.len() / 4;
        let mean = |e: &[f64]| e.iter().sum::<f64>() / e.len() as f64;
        // Rows grow downward: the receding end's edge is the smaller.
        let (left, right) = (mean(&edges[..quarter]), mean(&edges[edges.len() - quarter..]));
        if left >= right + SIDE_RISE_PX {
            Some(Side::Right)
        } else if right >= left + SIDE_RISE_PX {
            Some(Side::Left)
        } else {
            None
        }
    }

    /// The highest row above `bottom` (at most `max_rows` up) where the columns `u0..=u1`
    /// still differ from the background in the `flanks` columns beside them; None when nothing
    /// rises above the contact.
    fn top_row(
        &self,
        rgb: &[u8],
        w: usize,
        (u0, u1): (usize, usize),
        (bottom, max_rows): (usize, usize),
        flanks: [Option<usize>; 2],
    ) -> Option<usize> {
        let px = |u: usize, v: usize| {
            let i = (v * w + u) * 3;
            [rgb[i] as i32, rgb[i + 1] as i32, rgb[i + 2] as i32]
        };
        let diff = |a: [i32; 3], b: [i32; 3]| (a[0] - b[0]).abs() + (a[1] - b[1]).abs() + (a[2] - b[2]).abs();
        let mut top = None;
        let mut misses = 0;
        // A vehicle can show background between its parts (the road seen under it, a body
        // the colour of the road): gaps up to a sixth of the tallest vehicle are bridged.
        let max_gap = (max_rows / 6).max(3);
        let lowest = bottom.saturating_sub(max_rows);
        for v in (lowest..=bottom).rev() {
            let backgrounds: Vec<[i32; 3]> = flanks.into_iter().flatten().map(|u| px(u, v)).collect();
            if backgrounds.is_empty() {
                return None;
            }
            let step = ((u1 - u0) / 24).max(1);
            let (mut differ, mut total) = (0, 0);
            for u in (u0..=u1).step_by(step) {
                let c = px(u, v);
                total += 1;
                if backgrounds.iter().all(|b| diff(c, *b) > self.params.contrast) {
                    differ += 1;
                }
            }
            if differ * 10 >= total * 3 {
                top = Some(v);
                misses = 0;
            } else {
                misses += 1;
                if misses >= max_gap && top.is_some() {
                    break;
                }
            }
        }
        top
    }
}

/// Pixels of a lit lamp (LIT_RED_MIN, LIT_RED_OVER_GB) in the given columns and rows.
fn lit_pixels(
    rgb: &[u8],
    w: usize,
    columns: std::ops::RangeInclusive<usize>,
    rows: std::ops::RangeInclusive<usize>,
) -> u32 {
    let mut n = 0;
    for v in rows {
        let row = &rgb[v * w * 3..(v + 1) * w * 3];
        for px in row[columns.start() * 3..(columns.end() + 1).min(w) * 3].chunks_exact(3) {
            let (r, g, b) = (px[0], px[1] as i32, px[2] as i32);
            n += u32::from(r >= LIT_RED_MIN && r as i32 - g.max(b) >= LIT_RED_OVER_GB);
        }
    }
    n
}

/// Neighbouring columns (column, lowest row, highest row) where a thin band meets a tall dark
/// region a step lower: a far vehicle's contact band touching a nearer one's dark body or
/// glass in the image, not one band (a wheel at a band's side ends on the band's row).
fn thin_meets_tall(a: (u32, u32, u32), b: (u32, u32, u32)) -> bool {
    let (ta, tb) = (a.1 - a.2 + 1, b.1 - b.2 + 1);
    a.1.abs_diff(b.1) >= 2 && ta.max(tb) >= TALL_RATIO * ta.min(tb)
}

/// Whether a candidate with box `c` is part of the nearer vehicle with box `nearer`: its
/// contact line lies within that box and most of its columns under it (a dark window, a
/// black car's body, a rider's dark clothes).
pub(crate) fn part_of(c: &BoundingBox2d, nearer: &BoundingBox2d) -> bool {
    let overlap = c.u_max_px.min(nearer.u_max_px) - c.u_min_px.max(nearer.u_min_px);
    let width = c.u_max_px - c.u_min_px;
    overlap > 0.5 * width && c.v_max_px <= nearer.v_max_px && c.v_max_px >= nearer.v_min_px
}

fn median(mut xs: Vec<u8>) -> Option<f32> {
    xs.sort_unstable();
    xs.get(xs.len() / 2).map(|&x| x as f32)
}

/// Above this luma noise (standard deviation, levels) rows are smoothed before thresholding:
/// a camera with 9 levels of noise per channel (6 in luma) lost a third of the vehicles within
/// 60 m, and at 12 (8 in luma) two thirds, their contact bands broken up by the noise and the
/// road speckled with false dark pixels; the simulated cameras' default is 3 (2 in luma).
const SMOOTH_ABOVE_NOISE: f32 = 4.0;
/// Width of the smoothing window along a row, pixels (odd): noise / sqrt(5).
const SMOOTH_WINDOW: usize = 5;

/// The luma's noise (standard deviation, levels), from the lower ground's differences between
/// horizontal neighbours: their median absolute value is 0.954 sigma for Gaussian noise, and
/// edges (markings, vehicles) are too few to move the median.
fn luma_noise(luma: &[u8], w: usize, h: usize, first_row: usize) -> f32 {
    let mut hist = [0u32; 256];
    let mut n = 0u32;
    let start = (first_row + (h - first_row) / 3).min(h - 1);
    for v in (start..h).step_by(3) {
        let row = &luma[v * w..(v + 1) * w];
        for u in (w / 8..w * 7 / 8).step_by(2) {
            hist[row[u].abs_diff(row[u + 1]) as usize] += 1;
            n += 1;
        }
    }
    let mut seen = 0;
    let median = hist.iter().position(|&c| {
        seen += c;
        2 * seen > n
    });
    median.map_or(0.0, |m| m as f32 / 0.954)
}

/// `rgb` with each row's channels replaced by their moving average over SMOOTH_WINDOW pixels
/// (the window shrinks at the row's ends), into `out`. One pass per row, a running sum per
/// channel; the full window divides by multiplying (x / 5 = x * 13108 >> 16 for x <= 1275).
fn smooth_rows(rgb: &[u8], out: &mut Vec<u8>, w: usize) {
    const R: usize = SMOOTH_WINDOW / 2;
    const FULL: u32 = ((1 << 16) + SMOOTH_WINDOW as u32 - 1) / SMOOTH_WINDOW as u32;
    out.resize(rgb.len(), 0);
    if w <= SMOOTH_WINDOW {
        out.copy_from_slice(rgb);
        return;
    }
    for (src, dst) in rgb.chunks_exact(w * 3).zip(out.chunks_exact_mut(w * 3)) {
        let mut sum = [0u32; 3];
        for u in 0..R {
            for c in 0..3 {
                sum[c] += src[u * 3 + c] as u32;
            }
        }
        for u in 0..w {
            // The window is u - R ..= u + R, cut at the row's ends.
            if u + R < w {
                for c in 0..3 {
                    sum[c] += src[(u + R) * 3 + c] as u32;
                }
            }
            if u > R {
                for c in 0..3 {
                    sum[c] -= src[(u - R - 1) * 3 + c] as u32;
                }
            }
            let n = (u + R).min(w - 1) + 1 - u.saturating_sub(R);
            for c in 0..3 {
                dst[u * 3 + c] =
                    if n == SMOOTH_WINDOW { (sum[c] * FULL >> 16) as u8 } else { (sum[c] / n as u32) as u8 };
            }
        }
    }
}

/// The road's luminance: the mode of the lower middle of the image.
fn road_luma(luma: &[u8], w: usize, h: usize, first_row: usize) -> u8 {
    let mut hist = [0u32; 64];
    let start = (first_row + (h - first_row) / 3).min(h - 1);
    for v in (start..h).step_by(2) {
        for u in (w / 5..w * 4 / 5).step_by(2) {
            hist[(luma[v * w + u] >> 2) as usize] += 1;
        }
    }
    let mode = hist.iter().enumerate().max_by_key(|(_, n)| **n).map(|(i, _)| i).unwrap_or(32);
    (mode * 4 + 2) as u8
}

/// The class a band's size says: by height, and a band narrower than any car's, seen whole
/// (not cut by the image's side), under something as tall as a rider is a motorcycle.
fn class_of(width_m: f64, height_m: f64, whole: bool) -> ObjectClass {
    if height_m > 2.9 {
        ObjectClass::Truck
    } else if height_m > 1.9 {
        ObjectClass::Van
    } else if whole && width_m < MOTORCYCLE_MAX_WIDTH_M {
        ObjectClass::Motorcycle
    } else {
        ObjectClass::Car
    }
}

/// How plausible the size is for the class: 1 inside its width and height ranges, falling
/// with the ratio outside them, at least 0.05.
fn confidence_of(class: ObjectClass, width_m: f64, height_m: f64) -> f32 {
    let plausible = |x: f64, lo: f64, hi: f64| {
        if x < lo {
            x / lo
        } else if x > hi {
            hi / x
        } else {
            1.0
        }
    };
    let widths = if class == ObjectClass::Motorcycle { (0.6, 1.2) } else { (1.4, 2.8) };
    (plausible(width_m, widths.0, widths.1) * plausible(height_m, 1.1, 3.8)).clamp(0.05, 1.0) as f32
}

/// Splits one component's contact profile ((column, lowest row, highest row) per column) where
/// the contact row jumps or a column is missing: two vehicles whose dark bands touch in the
/// image stand at different distances. Stretches of two columns or more go to `out`.
fn split_profile(merged: &[(u32, u32, u32)], out: &mut Vec<Component>) {
    let mut start = 0;
    for i in 1..=merged.len() {
        let split = i == merged.len()
            || merged[i].0 != merged[i - 1].0 + 1
            || (merged[i].1 as i64 - merged[i - 1].1 as i64).abs() > JUMP_PX
            || thin_meets_tall(merged[i - 1], merged[i]);
        if split {
            if i - start >= 2 {
                out.push(component_of(merged, start, i));
            }
            start = i;
        }
    }
}

/// The stretch `merged[start..end]` of a contact profile as a component.
fn component_of(merged: &[(u32, u32, u32)], start: usize, end: usize) -> Component {
    let seg = &merged[start..end];
    // The flat lowest part is the rear edge (the side, if seen, rises away from it): it gives
    // the width and the centre.
    let v1 = seg.iter().map(|c| c.1).max().unwrap_or(0);
    let flat = seg.iter().filter(|c| c.1 + FLAT_PX >= v1);
    let (fu0, fu1) = flat.fold((u32::MAX, 0), |(a, b), c| (a.min(c.0), b.max(c.0)));
    // Dark columns joined to it on either side that end higher: the body over its wheels (a
    // bumper, a chassis), split off by the jump.
    let above = |c: &(u32, u32, u32)| c.1 <= v1;
    let mut reach_u0 = seg[0].0;
    for j in (0..start).rev() {
        if merged[j].0 + 1 != reach_u0 || !above(&merged[j]) {
            break;
        }
        reach_u0 = merged[j].0;
    }
    let mut reach_u1 = seg[seg.len() - 1].0;
    for c in &merged[end..] {
        if c.0 != reach_u1 + 1 || !above(c) {
            break;
        }
        reach_u1 = c.0;
    }
    Component { u0: seg[0].0, u1: seg[seg.len() - 1].0, v1, flat_u0: fu0, flat_u1: fu1, reach_u0, reach_u1 }
}

fn find(parent: &mut [u32], mut i: u32) -> u32 {
    while parent[i as usize] != i {
        parent[i as usize] = parent[parent[i as usize] as usize];
        i = parent[i as usize];
    }
    i
}

fn union(parent: &mut [u32], a: u32, b: u32) {
    let (ra, rb) = (find(parent, a), find(parent, b));
    if ra != rb {
        parent[ra.max(rb) as usize] = ra.min(rb);
    }
}
