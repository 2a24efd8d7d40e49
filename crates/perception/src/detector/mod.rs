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

mod lamps;
mod measure;
mod rejection;
mod segment;

use lamps::lit_pixels;
pub(crate) use measure::part_of;
pub(crate) use rejection::Rejection;
use segment::{luma_noise, road_luma, smooth_rows};

use super::geometry::CameraModel;
use slipstream_contract::msg::{BoundingBox2d, CameraInfo, ObjectClass};
use slipstream_model::vehicle::VehicleParams;

/// Tunable thresholds: the `detector` section of config/detect.json5, which documents each
/// and holds the defaults (what docs/perception.md measures).
#[derive(Debug, Clone, Copy, PartialEq, serde::Deserialize)]
#[serde(deny_unknown_fields)]
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
        crate::settings::DetectSettings::default().detector
    }
}

impl DetectorParams {
    /// The rules config/detect.json5 states for its `detector` section (`prefix`).
    pub fn check(&self, prefix: &str) -> Result<(), slipstream_contract::config::Invalid> {
        use crate::settings::{positive, range, share};
        share(&format!("{prefix}.dark_ratio"), f64::from(self.dark_ratio), false)?;
        share(&format!("{prefix}.band_ratio"), f64::from(self.band_ratio), false)?;
        range(prefix, ("min_width_m", self.min_width_m), ("max_width_m", self.max_width_m))?;
        range(prefix, ("min_height_m", self.min_height_m), ("max_height_m", self.max_height_m))?;
        positive(&format!("{prefix}.max_distance_m"), self.max_distance_m)?;
        if !(1..=765).contains(&self.contrast) {
            return slipstream_contract::config::Invalid::err(
                format!("{prefix}.contrast"),
                format!("{}", self.contrast),
                "give a colour difference from 1 to 765 (the sum over R, G and B)",
            );
        }
        Ok(())
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
/// Above this luma noise (standard deviation, levels) rows are smoothed before thresholding:
/// a camera with 9 levels of noise per channel (6 in luma) lost a third of the vehicles within
/// 60 m, and at 12 (8 in luma) two thirds, their contact bands broken up by the noise and the
/// road speckled with false dark pixels; the simulated cameras' default is 3 (2 in luma).
const SMOOTH_ABOVE_NOISE: f32 = 4.0;
/// Width of the smoothing window along a row, pixels (odd): noise / sqrt(5).
const SMOOTH_WINDOW: usize = 5;

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
        self.fill_luma(rgb);
        // A noisy sensor (low light, high gain): the frame is smoothed along its rows first,
        // which leaves the contact row (the range) where it is. Only then: the copy and the
        // luma again cost about 2 ms a frame for both cameras (docs/perception.md).
        if luma_noise(&self.luma, w, h, first_ground_row) > SMOOTH_ABOVE_NOISE {
            let mut smooth = std::mem::take(&mut self.smooth);
            smooth_rows(rgb, &mut smooth, w);
            self.fill_luma(&smooth);
            let found = self.detect_in(&smooth, first_ground_row);
            self.smooth = smooth;
            return found;
        }
        self.detect_in(rgb, first_ground_row)
    }

    /// The luma of an RGB8 frame.
    fn fill_luma(&mut self, rgb: &[u8]) {
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
}
