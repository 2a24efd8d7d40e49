//! What the viewer draws, built from the loop's messages in Foxglove's schemas: the camera
//! image, its annotations (detections, ground-truth boxes), the 3D scene (road, vehicles, the
//! ego's frame) and the ACC's series. Pure functions: the live view calls them at its own pace.

use foxglove::bytes::Bytes;
use foxglove::schemas::{
    line_primitive, points_annotation, scene_entity_deletion, CameraCalibration, Color, CompressedImage, CubePrimitive,
    FrameTransform, FrameTransforms, ImageAnnotations, LinePrimitive, Point2, Point3, PointsAnnotation, Pose,
    Quaternion, RawImage, SceneEntity, SceneEntityDeletion, SceneUpdate, TextAnnotation, Timestamp, Vector3,
};
use foxglove::Schema;
use nalgebra::Vector2;
use serde::Serialize;

use slipstream_contract::bus::FrameSample;
use slipstream_contract::msg::{
    AccMode, AccStatus, CameraInfo, Detections, GroundTruthObjects, ImageEncoding, VehicleState,
};
use slipstream_model::road::Road;
use slipstream_model::vehicle::VehicleParams;
use slipstream_sim::Scenario;

/// The fixed frame of the scene (the simulator's world), and the ego's, which follows it.
pub(crate) const FRAME_WORLD: &str = "world";
pub(crate) const FRAME_EGO: &str = "ego";
/// The camera image's frame.
pub(crate) const FRAME_CAMERA: &str = "camera_front";

/// How much road the scene draws behind and ahead of the ego, and its sample spacing.
const ROAD_BEHIND_M: f64 = 50.0;
const ROAD_AHEAD_M: f64 = 250.0;
const ROAD_STEP_M: f64 = 5.0;

const GREEN: Color = rgba(0.2, 0.85, 0.3, 1.0);
const ORANGE: Color = rgba(1.0, 0.55, 0.0, 1.0);
const CYAN: Color = rgba(0.25, 0.7, 1.0, 1.0);
const GREY: Color = rgba(0.6, 0.6, 0.65, 1.0);
const EGO_BLUE: Color = rgba(0.2, 0.4, 1.0, 1.0);
const WHITE: Color = rgba(0.95, 0.95, 0.95, 1.0);
const BLACK_BG: Color = rgba(0.0, 0.0, 0.0, 0.6);

const fn rgba(r: f64, g: f64, b: f64, a: f64) -> Color {
    Color { r, g, b, a }
}

/// A wall-clock or simulated time in nanoseconds as Foxglove's timestamp.
pub(crate) fn timestamp(ns: u64) -> Timestamp {
    Timestamp::new((ns / 1_000_000_000) as u32, (ns % 1_000_000_000) as u32)
}

/// The camera frame in the schema Foxglove's Image panel shows.
pub(crate) enum Image {
    Raw(RawImage),
    Compressed(CompressedImage),
}

/// The pixels of a received frame as `Bytes` that keep the Zenoh payload alive instead of
/// copying it: the one copy a viewed frame costs is the encoding into the viewer's message.
struct Payload(FrameSample);

impl AsRef<[u8]> for Payload {
    fn as_ref(&self) -> &[u8] {
        self.0.bytes()
    }
}

/// The frame as an image message, its pixels borrowed from the payload (LZ4 frames decoded);
/// None for a frame that does not decode.
pub(crate) fn image(sample: FrameSample) -> Option<Image> {
    let frame = sample.frame();
    let (stamp, f) = (frame.header.stamp_pub_ns, frame.msg);
    let offset = f.data.as_ptr() as usize - sample.bytes().as_ptr() as usize;
    let (width, height, encoding, len) = (f.width, f.height, f.encoding, f.data.len());
    let data = Bytes::from_owner(Payload(sample)).slice(offset..offset + len);
    frame_image(stamp, width, height, encoding, data)
}

/// A frame of `width` x `height` in `encoding`, its pixels `data`, as an image message: raw
/// pixels as RawImage, JPEG and PNG as CompressedImage, LZ4 decoded into a RawImage (Foxglove
/// does not read LZ4). None when an LZ4 frame does not decode.
pub(crate) fn frame_image(
    stamp_ns: u64,
    width: u32,
    height: u32,
    encoding: ImageEncoding,
    data: Bytes,
) -> Option<Image> {
    let stamp = Some(timestamp(stamp_ns));
    let frame_id = FRAME_CAMERA.to_string();
    Some(match encoding {
        ImageEncoding::Lz4 => {
            let rgb = match slipstream_contract::msg::decode_pixels(&data, width, height, encoding) {
                Ok(rgb) => rgb.into_owned(),
                Err(e) => {
                    tracing::debug!("frame not shown: {e}");
                    return None;
                }
            };
            return frame_image(stamp_ns, width, height, ImageEncoding::Rgb8, Bytes::from(rgb));
        }
        ImageEncoding::Rgb8 => Image::Raw(RawImage {
            timestamp: stamp,
            frame_id,
            width,
            height,
            encoding: "rgb8".into(),
            step: width * 3,
            data,
        }),
        ImageEncoding::Jpeg => {
            Image::Compressed(CompressedImage { timestamp: stamp, frame_id, data, format: "jpeg".into() })
        }
        ImageEncoding::Png => {
            Image::Compressed(CompressedImage { timestamp: stamp, frame_id, data, format: "png".into() })
        }
    })
}

/// The camera's intrinsics (a pinhole without distortion, as rendered), so the Image panel
/// knows the image's geometry.
pub(crate) fn calibration(stamp_ns: u64, info: &CameraInfo) -> CameraCalibration {
    let (fx, fy, cx, cy) = (info.fx_px, info.fy_px, info.cx_px, info.cy_px);
    CameraCalibration {
        timestamp: Some(timestamp(stamp_ns)),
        frame_id: FRAME_CAMERA.into(),
        width: info.width,
        height: info.height,
        distortion_model: "plumb_bob".into(),
        d: vec![0.0; 5],
        k: vec![fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0],
        r: vec![1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
        p: vec![fx, 0.0, cx, 0.0, 0.0, fy, cy, 0.0, 0.0, 0.0, 1.0, 0.0],
    }
}

fn box_outline(b: &slipstream_contract::msg::BoundingBox2d, color: Color, thickness: f64) -> PointsAnnotation {
    let p = |x: f32, y: f32| Point2 { x: x as f64, y: y as f64 };
    PointsAnnotation {
        r#type: points_annotation::Type::LineLoop as i32,
        points: vec![
            p(b.u_min_px, b.v_min_px),
            p(b.u_max_px, b.v_min_px),
            p(b.u_max_px, b.v_max_px),
            p(b.u_min_px, b.v_max_px),
        ],
        outline_color: Some(color),
        thickness,
        ..Default::default()
    }
}

/// Boxes on the camera image: ground truth thin and cyan, detections green with their track
/// and distance, the ACC's lead (a track id in camera perception) thick and orange.
/// Stamped with the frame the detections came from, so the Image panel pairs them.
pub(crate) fn annotations(
    stamp_ns: u64,
    detections: Option<&Detections>,
    truth: Option<&GroundTruthObjects>,
    lead_track: Option<u32>,
) -> ImageAnnotations {
    let mut a = ImageAnnotations { timestamp: Some(timestamp(stamp_ns)), ..Default::default() };
    for o in truth.iter().flat_map(|t| &t.objects) {
        if let Some(b) = o.image_box() {
            a.points.push(box_outline(b, CYAN, 1.0));
        }
    }
    for d in detections.iter().flat_map(|d| &d.detections) {
        let lead = lead_track == Some(d.track_id);
        let color = if lead { ORANGE } else { GREEN };
        a.points.push(box_outline(&d.bbox, color, if lead { 3.0 } else { 2.0 }));
        a.texts.push(TextAnnotation {
            position: Some(Point2 { x: d.bbox.u_min_px as f64, y: (d.bbox.v_min_px as f64 - 14.0).max(0.0) }),
            text: format!("#{} {:.0} m{}", d.track_id, d.distance_m, if lead { " lead" } else { "" }),
            font_size: 12.0,
            text_color: Some(color),
            background_color: Some(BLACK_BG),
            ..Default::default()
        });
    }
    a
}

fn yaw_quaternion(yaw: f64) -> Quaternion {
    Quaternion { x: 0.0, y: 0.0, z: (yaw / 2.0).sin(), w: (yaw / 2.0).cos() }
}

/// A vehicle's body as a cube: positions on the bus are the rear axle on the ground.
fn body(rear_axle: [f64; 3], yaw: f64, params: &VehicleParams, color: Color) -> CubePrimitive {
    let ahead = params.center_ahead_of_rear_axle_m();
    let [l, w, h] = params.size_m;
    CubePrimitive {
        pose: Some(Pose {
            position: Some(Vector3 {
                x: rear_axle[0] + ahead * yaw.cos(),
                y: rear_axle[1] + ahead * yaw.sin(),
                z: h / 2.0,
            }),
            orientation: Some(yaw_quaternion(yaw)),
        }),
        size: Some(Vector3 { x: l, y: w, z: h }),
        color: Some(color),
    }
}

fn entity(stamp_ns: u64, id: String, cube: CubePrimitive) -> SceneEntity {
    SceneEntity {
        timestamp: Some(timestamp(stamp_ns)),
        frame_id: FRAME_WORLD.into(),
        id,
        cubes: vec![cube],
        ..Default::default()
    }
}

/// The vehicles: the ego blue, the true lead (nearest ahead in the ego's lane) orange, the
/// others grey. Replaces the previous update whole, so vehicles that left are gone.
pub(crate) fn vehicles(
    stamp_ns: u64,
    ego: &VehicleState,
    ego_params: &VehicleParams,
    truth: Option<&GroundTruthObjects>,
) -> SceneUpdate {
    let mut entities =
        vec![entity(stamp_ns, "ego".into(), body(ego.position_in_world_m, ego.yaw_in_world_rad, ego_params, EGO_BLUE))];
    let lead = truth.and_then(|t| t.nearest_ahead_in_lane(ego.lane)).map(|l| l.id);
    for o in truth.iter().flat_map(|t| &t.objects) {
        let color = if lead == Some(o.id) { ORANGE } else { GREY };
        let params = VehicleParams::of_class(o.class);
        entities.push(entity(
            stamp_ns,
            format!("vehicle/{}", o.id),
            body(o.position_in_world_m, o.yaw_in_world_rad, &params, color),
        ));
    }
    SceneUpdate {
        deletions: vec![SceneEntityDeletion {
            timestamp: Some(timestamp(stamp_ns)),
            r#type: scene_entity_deletion::Type::All as i32,
            id: String::new(),
        }],
        entities,
    }
}

/// One line painted on the road, in world coordinates.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct RoadLine {
    /// The road's edge (solid white), or a lane divider (grey).
    pub edge: bool,
    pub points: Vec<Vector2<f64>>,
}

/// The road around `s_m` (the ego's distance along it): the lane boundaries as lines, the
/// road's edges moving in over a lane's taper where it ends.
pub(crate) fn road_lines(road: &Road, s_m: f64) -> Vec<RoadLine> {
    let n = ((ROAD_BEHIND_M + ROAD_AHEAD_M) / ROAD_STEP_M) as usize + 1;
    let lanes = road.lanes();
    (0..=lanes)
        .map(|i| {
            let d = i as f64 * road.lane_width_m() - road.half_width_m();
            let points = (0..n)
                .map(|k| {
                    let s = s_m - ROAD_BEHIND_M + k as f64 * ROAD_STEP_M;
                    // The edges move in where an outer lane ends.
                    let d = if i == 0 {
                        road.edges_d(s).0
                    } else if i == lanes {
                        road.edges_d(s).1
                    } else {
                        d
                    };
                    road.to_world(s, d)
                })
                .collect();
            RoadLine { edge: i == 0 || i == lanes, points }
        })
        .collect()
}

/// The road's lines for the 3D panel: edges solid white, lane dividers grey.
pub(crate) fn road_update(stamp_ns: u64, lines: &[RoadLine]) -> SceneUpdate {
    let lines = lines
        .iter()
        .map(|line| LinePrimitive {
            r#type: line_primitive::Type::LineStrip as i32,
            pose: Some(Pose { position: Some(Vector3::default()), orientation: Some(yaw_quaternion(0.0)) }),
            thickness: if line.edge { 0.3 } else { 0.15 },
            points: line.points.iter().map(|p| Point3 { x: p.x, y: p.y, z: 0.02 }).collect(),
            color: Some(if line.edge { WHITE } else { GREY }),
            ..Default::default()
        })
        .collect();
    SceneUpdate {
        deletions: Vec::new(),
        entities: vec![SceneEntity {
            timestamp: Some(timestamp(stamp_ns)),
            frame_id: FRAME_WORLD.into(),
            id: "road".into(),
            lines,
            ..Default::default()
        }],
    }
}

/// What the drawings know of a run beyond its messages: the road and the ego's vehicle type
/// (from the scenario), and where along the road the ego was last. One for the live view and
/// one for a recording's copies.
#[derive(Debug, Clone, Default)]
pub struct SceneContext {
    road: Option<Road>,
    road_s: Option<f64>,
    ego: Option<VehicleParams>,
}

impl SceneContext {
    /// The road and ego of `scenario`, when it is known.
    pub fn of(scenario: Option<&Scenario>) -> SceneContext {
        SceneContext {
            road: scenario.map(|s| Road::new(s.road.clone())),
            road_s: None,
            ego: scenario.map(|s| VehicleParams::of_class(s.ego().class.into())),
        }
    }

    /// The road the simulator publishes (sim/road), taken when none is known yet: any
    /// simulator's, a scenario file's, a running loop's that the view joined late.
    pub fn published(&mut self, road: slipstream_contract::msg::RoadSpec) {
        if self.road.is_none() {
            self.road = Some(Road::new(road));
            self.road_s = None;
        }
    }

    /// The scenario the simulator announced (sim/events), taken when none is known yet and
    /// it is a built-in one.
    pub fn announced(&mut self, name: &str) {
        if self.road.is_none() {
            if let Ok(s) = Scenario::find(name) {
                *self = SceneContext::of(Some(&s));
            }
        }
    }

    /// The ego's vehicle type: the scenario's, else a car.
    pub fn ego(&self) -> VehicleParams {
        self.ego.unwrap_or(VehicleParams::CAR)
    }

    /// The road's lines around the ego (none without a scenario); the ego's place along it is
    /// searched near the last one.
    pub(crate) fn road_around(&mut self, ego: &VehicleState) -> Option<Vec<RoadLine>> {
        let road = self.road.as_ref()?;
        let p = Vector2::new(ego.position_in_world_m[0], ego.position_in_world_m[1]);
        let s_m = match self.road_s {
            Some(h) => road.project(p, h).0,
            None => road.project_anywhere(p).0,
        };
        self.road_s = Some(s_m);
        Some(road_lines(road, s_m))
    }
}

/// world -> ego: lets the 3D panel follow the ego (display frame `ego`).
pub(crate) fn ego_frame(stamp_ns: u64, ego: &VehicleState) -> FrameTransforms {
    let p = ego.position_in_world_m;
    FrameTransforms {
        transforms: vec![FrameTransform {
            timestamp: Some(timestamp(stamp_ns)),
            parent_frame_id: FRAME_WORLD.into(),
            child_frame_id: FRAME_EGO.into(),
            translation: Some(Vector3 { x: p[0], y: p[1], z: p[2] }),
            rotation: Some(yaw_quaternion(ego.yaw_in_world_rad)),
        }],
    }
}

/// One sample of the ACC's series for the Plot and Raw Message panels (JSON): what it sees,
/// wants and does, on simulated time.
#[derive(Debug, Clone, PartialEq, Serialize, schemars::JsonSchema)]
pub(crate) struct AccSeries {
    pub t_s: f64,
    pub speed_mps: f64,
    pub accel_mps2: f64,
    pub set_speed_mps: Option<f64>,
    pub time_gap_s: Option<f64>,
    /// The ACC's mode by name (Off, Speed, Follow, Stale, Emergency).
    #[schemars(with = "Option<String>")]
    pub mode: Option<AccMode>,
    pub gap_m: Option<f64>,
    pub desired_gap_m: Option<f64>,
    pub ttc_s: Option<f64>,
    /// The true gap to the true lead, for comparison with what the ACC measured.
    pub truth_gap_m: Option<f64>,
    pub warnings: Vec<String>,
}

/// The series sample from the latest state, status and ground truth.
pub(crate) fn acc_series(
    ego: &VehicleState,
    stamp_sim_ns: u64,
    ego_params: &VehicleParams,
    status: Option<&AccStatus>,
    truth: Option<&GroundTruthObjects>,
) -> AccSeries {
    let front = ego_params.size_m[0] - ego_params.rear_overhang_m;
    let lead = status.and_then(|s| s.lead.as_ref());
    AccSeries {
        t_s: stamp_sim_ns as f64 / 1e9,
        speed_mps: ego.speed_mps,
        accel_mps2: ego.acceleration_in_body_mps2[0],
        set_speed_mps: status.map(|s| s.set_speed_mps),
        time_gap_s: status.map(|s| s.time_gap_s),
        mode: status.map(|s| s.mode),
        gap_m: lead.map(|l| l.gap_m),
        desired_gap_m: lead.map(|l| l.desired_gap_m),
        ttc_s: lead.and_then(|l| l.ttc_s),
        truth_gap_m: truth.and_then(|t| t.nearest_ahead_in_lane(ego.lane)).map(|o| o.position_in_ego_m[0] - front),
        warnings: status.map(|s| s.warnings.iter().map(|w| format!("{w:?}")).collect()).unwrap_or_default(),
    }
}

/// The JSON schema of [`AccSeries`], for the channel's advertisement: derived from the type
/// (draft 7, definitions inline: Foxglove resolves no references), with an optional field's
/// type the value's own (`"number"`, not `["number", "null"]`): Foxglove's and Lichtblick's
/// schema readers take one type per field, and an absent sample is null either way.
pub(crate) fn acc_series_schema() -> Schema {
    let settings = schemars::generate::SchemaSettings::draft07().with(|s| s.inline_subschemas = true);
    let schema = settings.into_generator().into_root_schema_for::<AccSeries>();
    let mut json = serde_json::to_value(&schema).unwrap_or_default();
    single_types(&mut json);
    Schema::new(ACC_SERIES_SCHEMA, "jsonschema", serde_json::to_vec(&json).unwrap_or_default())
}

/// `"type": [T, "null"]` -> `"type": T`, everywhere in a schema.
fn single_types(v: &mut serde_json::Value) {
    match v {
        serde_json::Value::Object(map) => {
            if let Some(serde_json::Value::Array(types)) = map.get("type") {
                let named: Vec<_> = types.iter().filter(|t| t.as_str() != Some("null")).cloned().collect();
                if let [only] = named.as_slice() {
                    map.insert("type".into(), only.clone());
                }
            }
            map.values_mut().for_each(single_types);
        }
        serde_json::Value::Array(items) => items.iter_mut().for_each(single_types),
        _ => {}
    }
}

/// The name of [`acc_series_schema`].
pub(crate) const ACC_SERIES_SCHEMA: &str = "slipstream.view.AccSeries";

#[cfg(test)]
mod tests {
    use super::*;
    use slipstream_contract::msg::{BoundingBox2d, Detection, GroundTruthObject, ObjectClass};

    fn state(x: f64, yaw: f64, lane: i32) -> VehicleState {
        VehicleState {
            position_in_world_m: [x, 0.0, 0.0],
            yaw_in_world_rad: yaw,
            lane,
            ..slipstream_contract::msg::example_state()
        }
    }

    fn object(id: u32, x_world: f64, x_ego: f64, lane: i32, bbox: Option<BoundingBox2d>) -> GroundTruthObject {
        GroundTruthObject {
            id,
            class: ObjectClass::Truck,
            size_m: VehicleParams::TRUCK.size_m,
            lane,
            position_in_world_m: [x_world, 0.0, 0.0],
            yaw_in_world_rad: 0.0,
            velocity_in_world_mps: [18.0, 0.0, 0.0],
            position_in_ego_m: [x_ego, 0.0, 1.0],
            yaw_in_ego_rad: 0.0,
            velocity_in_ego_mps: [-2.0, 0.0, 0.0],
            bbox,
            visible_fraction: 1.0,
            brake_lights: false,
        }
    }

    const BOX: BoundingBox2d = BoundingBox2d { u_min_px: 300.0, v_min_px: 230.0, u_max_px: 340.0, v_max_px: 262.0 };

    #[test]
    fn boxes_are_closed_outlines_with_the_lead_set_apart() {
        let det = |id| Detection {
            track_id: id,
            class: ObjectClass::Car,
            bbox: BOX,
            confidence: 0.9,
            distance_m: 27.4,
            lateral_offset_m: 0.0,
            relative_speed_mps: -1.0,
            distance_sigma_m: 0.1,
            relative_speed_sigma_mps: 0.2,
            brake_lights: false,
        };
        let detections =
            Detections { frame_seq: 3, frame_stamp_pub_ns: 5_250_000_000, detections: vec![det(1), det(2)] };
        let hidden = GroundTruthObject { visible_fraction: 0.0, ..object(9, 80.0, 30.0, 1, Some(BOX)) };
        let truth = GroundTruthObjects {
            step: 9,
            objects: vec![object(7, 60.0, 30.0, 1, Some(BOX)), object(8, 90.0, 60.0, 0, None), hidden],
        };
        let a = annotations(5_250_000_000, Some(&detections), Some(&truth), Some(2));
        assert_eq!(a.timestamp, Some(Timestamp::new(5, 250_000_000)));
        // One ground-truth box (one has no box in the image, one is wholly hidden behind a
        // nearer car: no miss to draw), two detections.
        assert_eq!(a.points.len(), 3);
        assert!(a.points.iter().all(|p| p.points.len() == 4 && p.r#type == points_annotation::Type::LineLoop as i32));
        assert_eq!(a.points[0].outline_color, Some(CYAN));
        assert_eq!(a.points[1].outline_color, Some(GREEN));
        assert_eq!(a.points[2].outline_color, Some(ORANGE));
        assert_eq!(a.points[2].points[2], Point2 { x: 340.0, y: 262.0 });
        assert_eq!(a.texts.iter().map(|t| t.text.as_str()).collect::<Vec<_>>(), ["#1 27 m", "#2 27 m lead"]);
        assert!(annotations(0, None, None, None).points.is_empty());
    }

    #[test]
    fn cubes_sit_on_the_road_around_the_body_centre_and_the_lead_is_orange() {
        let ego = state(10.0, 0.0, 1);
        let truth = GroundTruthObjects {
            step: 1,
            objects: vec![object(7, 60.0, 45.0, 1, None), object(8, 30.0, 15.0, 0, None)],
        };
        let update = vehicles(1, &ego, &VehicleParams::CAR, Some(&truth));
        assert_eq!(update.deletions.len(), 1, "each update replaces the last: vehicles that left disappear");
        let ids: Vec<&str> = update.entities.iter().map(|e| e.id.as_str()).collect();
        assert_eq!(ids, ["ego", "vehicle/7", "vehicle/8"]);
        let cube = |i: usize| update.entities[i].cubes[0];
        let ego_centre = cube(0).pose.unwrap().position.unwrap();
        assert!((ego_centre.x - (10.0 + VehicleParams::CAR.center_ahead_of_rear_axle_m())).abs() < 1e-9);
        assert!((ego_centre.z - VehicleParams::CAR.size_m[2] / 2.0).abs() < 1e-9);
        assert_eq!(cube(1).size.unwrap().x, VehicleParams::TRUCK.size_m[0]);
        assert_eq!(cube(1).color, Some(ORANGE), "the nearest vehicle ahead in the ego's lane");
        assert_eq!(cube(2).color, Some(GREY), "another lane");
        // Heading 90 degrees: the body centre moves along y.
        let turned = vehicles(1, &state(0.0, std::f64::consts::FRAC_PI_2, 1), &VehicleParams::CAR, None);
        let c = turned.entities[0].cubes[0].pose.unwrap().position.unwrap();
        assert!(c.x.abs() < 1e-9 && c.y > 1.0);
    }

    #[test]
    fn the_road_has_one_line_per_lane_boundary_around_the_ego() {
        let spec = slipstream_model::road::RoadSpec::default();
        let r = Road::new(spec.clone());
        let update = road_update(1, &road_lines(&r, 100.0));
        let lines = &update.entities[0].lines;
        assert_eq!(lines.len(), spec.lanes as usize + 1);
        let first = &lines[0].points;
        assert!((first[0].x - 50.0).abs() < 1e-6, "starts {ROAD_BEHIND_M} m behind: {}", first[0].x);
        assert!((first.last().unwrap().x - 350.0).abs() < 1e-6);
        assert!((first[0].y + r.half_width_m()).abs() < 1e-6);
        assert_eq!(lines[0].color, Some(WHITE));
        assert_eq!(lines[1].color, Some(GREY));
    }

    #[test]
    fn the_series_pairs_what_the_acc_measured_with_the_truth() {
        let ego = state(10.0, 0.0, 1);
        let status = AccStatus {
            mode: AccMode::Follow,
            set_speed_mps: 30.0,
            time_gap_s: 1.8,
            lead: Some(slipstream_contract::msg::LeadInfo {
                id: 2,
                gap_m: 40.5,
                desired_gap_m: 38.0,
                relative_speed_mps: -2.0,
                ttc_s: Some(20.0),
            }),
            ..slipstream_contract::msg::example_status()
        };
        let truth = GroundTruthObjects { step: 1, objects: vec![object(7, 60.0, 45.0, 1, None)] };
        let s = acc_series(&ego, 2_500_000_000, &VehicleParams::CAR, Some(&status), Some(&truth));
        assert_eq!(s.t_s, 2.5);
        assert_eq!(s.gap_m, Some(40.5));
        let front = VehicleParams::CAR.size_m[0] - VehicleParams::CAR.rear_overhang_m;
        assert_eq!(s.truth_gap_m, Some(45.0 - front));
        let json = serde_json::to_value(&s).unwrap();
        assert_eq!(json["mode"], "Follow");
        let schema: serde_json::Value = serde_json::from_slice(&acc_series_schema().data).unwrap();
        for key in json.as_object().unwrap().keys() {
            assert!(schema["properties"].get(key).is_some(), "{key} missing from the schema");
        }
        // One type per field: Foxglove's and Lichtblick's readers refuse a type list.
        assert_eq!(schema["properties"]["gap_m"]["type"], "number");
        assert_eq!(schema["properties"]["mode"]["type"], "string");
        assert!(!schema.to_string().contains("\"null\""), "{schema}");
        let bare = acc_series(&ego, 0, &VehicleParams::CAR, None, None);
        assert_eq!((bare.mode, bare.gap_m, bare.truth_gap_m), (None, None, None));
    }
}
