//! The ego's cameras together: the front camera and, when the vehicle has one, the narrow-angle
//! camera beside it. Each frame pair gives one list of vehicles, each vehicle once, measured by
//! the camera that sees it best, then tracked.
//!
//! A vehicle far ahead is a few pixels through the front camera and three times as many
//! through the narrow one, which measures it; near or off to the side the narrow camera sees a
//! vehicle cut by its image's border (or not at all) and the front camera measures it. Boxes are
//! always in the front camera's image, the image the detections' boxes refer to
//! (docs/wire-format.md), so a narrow camera's box is mapped into it through the vehicle's
//! measured distance.

use super::detector::{part_of, Detector, DetectorParams, FrameDetection};
use super::settings::{DetectSettings, FusionParams};
use super::tracker::Tracker;
use slipstream_contract::msg::{BoundingBox2d, CameraInfo, Detection};

/// A box within this many pixels of an image border is cut by it (or may be).
const BORDER_PX: f32 = 1.0;

/// Detection and tracking over the front camera and an optional narrow one.
pub struct CameraRig {
    front: Detector,
    narrow: Option<Detector>,
    tracker: Tracker,
    fusion: FusionParams,
}

impl CameraRig {
    /// Detectors for the cameras `front` and `narrow` describe. The narrow camera's farthest
    /// distance is the front one's scaled by their focal lengths: a vehicle is as many pixels
    /// wide at either limit.
    pub fn new(front: &CameraInfo, narrow: Option<&CameraInfo>, settings: &DetectSettings) -> CameraRig {
        let params = settings.detector;
        let narrow = narrow.map(|n| {
            let scale = (n.fx_px / front.fx_px).max(1.0);
            Detector::new(n, DetectorParams { max_distance_m: params.max_distance_m * scale, ..params })
        });
        let tracker = Tracker::new(settings.tracker);
        CameraRig { front: Detector::new(front, params), narrow, tracker, fusion: settings.fusion }
    }

    pub fn narrow(&self) -> Option<&CameraInfo> {
        self.narrow.as_ref().map(|d| &d.camera().info)
    }

    /// Vehicles in one frame of each camera (the narrow camera's of the same instant, when
    /// there is one), each once; not tracked.
    pub fn detect(&mut self, front_rgb: &[u8], narrow_rgb: Option<&[u8]>) -> Vec<FrameDetection> {
        let front = self.front.detect(front_rgb);
        match (self.narrow.as_mut(), narrow_rgb) {
            (Some(narrow), Some(rgb)) => {
                let far = narrow.detect(rgb);
                fuse(front, far, narrow, &self.front, self.fusion)
            }
            _ => front,
        }
    }

    /// [`CameraRig::detect`], then tracking at simulation time `t_s`.
    pub fn update(&mut self, front_rgb: &[u8], narrow_rgb: Option<&[u8]>, t_s: f64) -> Vec<Detection> {
        let found = self.detect(front_rgb, narrow_rgb);
        self.tracker.update(&found, t_s)
    }
}

fn near_border(b: &BoundingBox2d, info: &CameraInfo) -> bool {
    b.u_min_px <= BORDER_PX
        || b.v_min_px <= BORDER_PX
        || b.u_max_px >= info.width as f32 - BORDER_PX
        || b.v_max_px >= info.height as f32 - BORDER_PX
}

/// One list from the front camera's detections and the narrow camera's: a vehicle both see is
/// kept as the narrow camera measured it when it lies whole inside that camera's image, as
/// the front camera did otherwise. Narrow boxes are mapped into the front image.
fn fuse(
    front: Vec<FrameDetection>,
    far: Vec<FrameDetection>,
    narrow: &Detector,
    wide: &Detector,
    p: FusionParams,
) -> Vec<FrameDetection> {
    let same = |a: &FrameDetection, b: &FrameDetection| {
        (a.distance_m - b.distance_m).abs() < (p.same_distance_share * b.distance_m).max(p.same_min_m)
            && (a.lateral_offset_m - b.lateral_offset_m).abs() < p.same_lateral_m
    };
    let mut out = front;
    for mut n in far {
        let whole = !near_border(&n.bbox, &narrow.camera().info);
        let twin = out.iter().position(|f| same(f, &n));
        match (twin, whole) {
            // The front camera measured it and the narrow one sees it cut: keep the front's.
            (Some(_), false) => continue,
            (Some(i), true) => {
                n.bbox = to_image_of(wide, narrow, &n);
                // Lamps seen lit by either camera are lit.
                n.brake_lights |= out[i].brake_lights;
                out[i] = n;
            }
            (None, _) => {
                n.bbox = to_image_of(wide, narrow, &n);
                // The narrow camera sees the ground only from ~16 m: a nearer vehicle's body
                // (its contact below the image) can pass for a far one; in the front image it
                // lies on that vehicle.
                if !out.iter().any(|f| f.distance_m < n.distance_m && part_of(&n.bbox, &f.bbox)) {
                    out.push(n);
                }
            }
        }
    }
    out
}

/// A narrow camera's box in the front camera's image: its corners' rays taken to the
/// vehicle's measured distance and projected.
fn to_image_of(wide: &Detector, narrow: &Detector, d: &FrameDetection) -> BoundingBox2d {
    let (n, w) = (narrow.camera(), wide.camera());
    let o = n.origin_in_body();
    let corner = |u: f32, v: f32| {
        let r = n.ray_in_body(u as f64, v as f64);
        let p = o + r * ((d.distance_m - o.x) / r.x.max(1e-9));
        w.project(&p).unwrap_or((w.info.cx_px, w.info.cy_px))
    };
    let b = &d.bbox;
    let (a, c) = (corner(b.u_min_px, b.v_min_px), corner(b.u_max_px, b.v_max_px));
    BoundingBox2d {
        u_min_px: a.0.min(c.0) as f32,
        v_min_px: a.1.min(c.1) as f32,
        u_max_px: a.0.max(c.0) as f32,
        v_max_px: a.1.max(c.1) as f32,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use slipstream_contract::msg::{ImageEncoding, ObjectClass};

    fn info(w: u32, h: u32, fov_deg: f64, pitch_deg: f64) -> CameraInfo {
        CameraInfo::pinhole(
            w,
            h,
            fov_deg.to_radians(),
            [1.6, 0.0, 1.35],
            [0.0, pitch_deg.to_radians(), 0.0],
            20.0,
            ImageEncoding::Rgb8,
        )
    }

    fn det(distance_m: f64, lateral_offset_m: f64, bbox: [f32; 4]) -> FrameDetection {
        FrameDetection {
            bbox: BoundingBox2d { u_min_px: bbox[0], v_min_px: bbox[1], u_max_px: bbox[2], v_max_px: bbox[3] },
            class: ObjectClass::Car,
            distance_m,
            distance_sigma_m: 0.1,
            lateral_offset_m,
            height_m: 1.5,
            width_m: 1.8,
            confidence: 1.0,
            brake_lights: false,
        }
    }

    #[test]
    fn a_vehicle_both_cameras_see_is_kept_once_as_the_better_one_measured_it() {
        let (front, narrow) = (info(640, 480, 60.0, 3.0), info(640, 240, 20.0, 1.0));
        let (wide, tele) = (Detector::new(&front, Default::default()), Detector::new(&narrow, Default::default()));
        let fusion = DetectSettings::default().fusion;
        // Seen whole by both: the narrow camera's measurement, its box mapped into the front image.
        let fused = fuse(
            vec![det(71.0, 0.1, [313.0, 200.0, 327.0, 215.0])],
            vec![det(70.0, 0.0, [297.0, 80.0, 343.0, 120.0])],
            &tele,
            &wide,
            fusion,
        );
        assert_eq!(fused.len(), 1, "{fused:?}");
        assert_eq!(fused[0].distance_m, 70.0);
        let b = fused[0].bbox;
        let centre = (b.u_min_px + b.u_max_px) / 2.0;
        assert!((centre - 320.0).abs() < 0.5 && b.u_max_px - b.u_min_px < 16.0, "{b:?}");
        // Cut by the narrow image's side: the front camera's measurement stays.
        let fused = fuse(
            vec![det(30.0, -3.4, [100.0, 220.0, 160.0, 270.0])],
            vec![det(31.0, -3.0, [0.0, 80.0, 40.0, 200.0])],
            &tele,
            &wide,
            fusion,
        );
        assert_eq!((fused.len(), fused[0].distance_m), (1, 30.0), "{fused:?}");
        // Only the narrow camera sees it (too far for the front one): added.
        let fused = fuse(
            vec![det(20.0, 3.5, [500.0, 250.0, 560.0, 300.0])],
            vec![det(150.0, 0.0, [308.0, 88.0, 332.0, 106.0])],
            &tele,
            &wide,
            fusion,
        );
        assert_eq!(fused.len(), 2, "{fused:?}");
        assert!(fused[1].bbox.u_max_px - fused[1].bbox.u_min_px < 9.0, "{:?}", fused[1].bbox);
        // A "far" vehicle the narrow camera reads off a near one's body (its contact below
        // the narrow image) lies on the near one in the front image: dropped.
        let fused = fuse(
            vec![det(15.5, 0.0, [300.0, 213.0, 340.0, 265.0])],
            vec![det(41.3, 0.0, [262.0, 60.0, 378.0, 140.0])],
            &tele,
            &wide,
            fusion,
        );
        assert_eq!(fused.len(), 1, "{fused:?}");
    }
}
