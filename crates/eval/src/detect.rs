//! `slipstream eval detect`: runs scenarios in process (the simulator's world and renderer,
//! the ego driven like traffic: its start speed, slowing for the vehicle ahead), runs the
//! detector and tracker on every camera frame and scores it against the
//! ground truth of the same frame (same simulation step, so matching by time is exact).
//!
//! A ground-truth vehicle counts for recall when it is within `max_range_m` ahead and at least
//! `min_visible` visible (beyond, to its class's long range, for the long-range recall); a
//! detection is a true positive when it overlaps (IoU >= 0.3) any ground-truth vehicle in view,
//! near or far, or places its rear within 5 % of its distance and 1 m across (far vehicles
//! are a few pixels in the front image, where boxes are compared).

use serde::Serialize;

use super::bend_lateral::{self, LateralCell, RoadView};
use super::frame_detector::{FrameDetector, Ours};
use super::link_codec::{LinkCodec, LinkCost};
use slipstream_contract::msg::{Detection, GroundTruthObject};
use slipstream_launch::ForeignNode;
use slipstream_perception::DetectSettings;
use slipstream_sim::ground_truth;
use slipstream_sim::settings::SimSettings;
use slipstream_sim::world::{EgoInput, World};
use slipstream_sim::Cameras;
use slipstream_sim::Scenario;

pub const IOU_MATCH: f32 = 0.3;
/// An overlap match also needs the distance within this share of the true one.
pub(crate) const IOU_DISTANCE_SHARE: f64 = 0.3;

/// Distance bands errors are reported in.
pub(crate) const RANGES_M: [(f64, f64); 5] =
    [(0.0, 20.0), (20.0, 40.0), (40.0, 60.0), (60.0, 150.0), (150.0, f64::INFINITY)];

/// Beyond the near range, recall counts vehicles in full view (at least this visible): a
/// vehicle far ahead is partly hidden by a nearer one at its bottom, where the detector finds
/// vehicles (docs/perception.md).
pub(crate) const FAR_MIN_VISIBLE: f32 = 0.9;

/// Beyond the near range, the long range recall is counted to: cars and vans to 150 m,
/// trucks to 200 m (what an ACC needs at motorway speed, docs/perception.md).
pub(crate) fn long_range_m(class: slipstream_contract::msg::ObjectClass) -> f64 {
    match class {
        slipstream_contract::msg::ObjectClass::Truck => 200.0,
        _ => 150.0,
    }
}

/// A detection also matches a vehicle whose rear it places within this share of the
/// distance and `PLACED_LATERAL_M` across: a vehicle 150 m ahead is a few pixels in the front
/// image the boxes are in, and a box of a partly hidden one overlaps its whole box little.
pub(crate) const PLACED_DISTANCE_SHARE: f64 = 0.05;
pub(crate) const PLACED_LATERAL_M: f64 = 1.0;

/// How well `d` places `o` (1 exactly, towards 0 at the limits), None beyond them.
fn placed_on(d: &Detection, o: &GroundTruthObject) -> Option<f32> {
    let [x, y, _] = o.position_in_ego_m;
    let along = (d.distance_m - x).abs() / (PLACED_DISTANCE_SHARE * x);
    let across = (d.lateral_offset_m - y).abs() / PLACED_LATERAL_M;
    (x > 0.0 && along < 1.0 && across < 1.0).then(|| (1.0 - along.max(across)) as f32)
}

/// One matched pair's errors.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub(crate) struct MatchError {
    pub true_distance_m: f64,
    /// |estimated - true| / true.
    pub distance_rel: f64,
    pub lateral_abs_m: f64,
    /// Estimated - true lateral offset, positive left.
    pub lateral_signed_m: f64,
    /// The tightest bend (|radius|, m) between the ego and the vehicle; None on a straight.
    pub bend_radius_m: Option<f64>,
    /// Estimated - true place across the road (on the road's map, where each point falls),
    /// positive left.
    pub across_signed_m: f64,
    /// |estimated - true| relative speed, m/s, for tracks seen at least 3 times.
    pub relative_speed_abs_mps: Option<f64>,
}

/// Brake lights over matched detections.
#[derive(Debug, Clone, Copy, Default, Serialize)]
pub struct BrakeLightCounts {
    pub lit: u64,
    pub lit_seen: u64,
    pub unlit: u64,
    pub unlit_seen_lit: u64,
}

impl BrakeLightCounts {
    fn add(&mut self, truth: bool, seen: bool) {
        if truth {
            self.lit += 1;
            self.lit_seen += seen as u64;
        } else {
            self.unlit += 1;
            self.unlit_seen_lit += seen as u64;
        }
    }

    fn merge(&mut self, o: BrakeLightCounts) {
        self.lit += o.lit;
        self.lit_seen += o.lit_seen;
        self.unlit += o.unlit;
        self.unlit_seen_lit += o.unlit_seen_lit;
    }
}

/// Counts and errors accumulated over frames.
#[derive(Debug, Clone, Default, Serialize)]
pub(crate) struct Tally {
    pub frames: u64,
    /// Frames the detector left unanswered.
    pub unanswered_frames: u64,
    pub detections: u64,
    pub true_positives: u64,
    pub eligible: u64,
    pub eligible_found: u64,
    /// Vehicles in full view ([`FAR_MIN_VISIBLE`]) beyond the near range, to their class's
    /// long range ([`long_range_m`]): how many, how many found.
    pub far_eligible: u64,
    pub far_found: u64,
    pub errors: Vec<MatchError>,
    /// Matched vehicles by their true brake lights: lit, how many of those seen lit; unlit,
    /// how many of those seen lit.
    pub brake_lights: BrakeLightCounts,
    /// Times a ground-truth vehicle's matched track id changed.
    pub id_switches: u64,
    #[serde(skip)]
    last_track_of: std::collections::BTreeMap<u32, u32>,
}

impl Tally {
    /// Scores one frame: greedy matching by IoU, best pairs first; `view` names the bend each
    /// vehicle is seen through and places points across the road.
    pub(crate) fn add_frame(
        &mut self,
        dets: &[Detection],
        truth: &[GroundTruthObject],
        (max_range_m, min_visible): (f64, f32),
        view: &RoadView,
    ) {
        self.frames += 1;
        self.detections += dets.len() as u64;
        let in_view: Vec<&GroundTruthObject> =
            truth.iter().filter(|o| o.bbox.is_some() && o.visible_fraction > 0.0).collect();
        let mut pairs: Vec<(f32, usize, usize)> = Vec::new();
        for (i, d) in dets.iter().enumerate() {
            for (j, o) in in_view.iter().enumerate() {
                let score = d.bbox.iou(o.bbox.as_ref().unwrap_or(&d.bbox));
                // Overlapping boxes at distances far apart are two vehicles, one behind the other.
                let x = o.position_in_ego_m[0];
                if score >= IOU_MATCH && (d.distance_m - x).abs() < IOU_DISTANCE_SHARE * x.abs() {
                    pairs.push((score, i, j));
                } else if let Some(closeness) = placed_on(d, o) {
                    // Below any overlap match: boxes decide where they can.
                    pairs.push((closeness * IOU_MATCH, i, j));
                }
            }
        }
        pairs.sort_by(|a, b| b.0.total_cmp(&a.0));
        let (mut det_used, mut gt_used) = (vec![false; dets.len()], vec![false; in_view.len()]);
        for (_, i, j) in pairs {
            if det_used[i] || gt_used[j] {
                continue;
            }
            det_used[i] = true;
            gt_used[j] = true;
            self.true_positives += 1;
            let o = in_view[j];
            let d = &dets[i];
            self.brake_lights.add(o.brake_lights, d.brake_lights);
            let previous = self.last_track_of.insert(o.id, d.track_id);
            self.id_switches += previous.is_some_and(|p| p != d.track_id) as u64;
            // Relative speed is judged once the same track has held the vehicle for a frame.
            let settled = previous == Some(d.track_id);
            let truth_x = o.position_in_ego_m[0];
            if truth_x > 0.0 {
                self.errors.push(MatchError {
                    true_distance_m: truth_x,
                    distance_rel: (d.distance_m - truth_x).abs() / truth_x,
                    lateral_abs_m: (d.lateral_offset_m - o.position_in_ego_m[1]).abs(),
                    lateral_signed_m: d.lateral_offset_m - o.position_in_ego_m[1],
                    bend_radius_m: view.bend_of(o),
                    across_signed_m: view.across_m(d.distance_m, d.lateral_offset_m)
                        - view.across_m(truth_x, o.position_in_ego_m[1]),
                    relative_speed_abs_mps: (settled && d.relative_speed_mps != 0.0)
                        .then(|| (d.relative_speed_mps - o.velocity_in_ego_mps[0]).abs()),
                });
            }
        }
        for (j, o) in in_view.iter().enumerate() {
            let x = o.position_in_ego_m[0];
            if x <= 0.0 {
                continue;
            }
            if x <= max_range_m && o.visible_fraction >= min_visible {
                self.eligible += 1;
                self.eligible_found += gt_used[j] as u64;
            } else if x > max_range_m && x <= long_range_m(o.class) && o.visible_fraction >= FAR_MIN_VISIBLE {
                self.far_eligible += 1;
                self.far_found += gt_used[j] as u64;
            }
        }
    }

    pub(crate) fn precision(&self) -> f64 {
        if self.detections == 0 {
            1.0
        } else {
            self.true_positives as f64 / self.detections as f64
        }
    }

    pub(crate) fn recall(&self) -> f64 {
        if self.eligible == 0 {
            1.0
        } else {
            self.eligible_found as f64 / self.eligible as f64
        }
    }

    /// Recall beyond the near range, None when no vehicle was there.
    pub(crate) fn far_recall(&self) -> Option<f64> {
        (self.far_eligible > 0).then(|| self.far_found as f64 / self.far_eligible as f64)
    }

    /// (median, p90) of relative distance error for true distances in [lo, hi).
    pub(crate) fn distance_error(&self, lo: f64, hi: f64) -> Option<(f64, f64)> {
        percentiles(
            self.errors.iter().filter(|e| e.true_distance_m >= lo && e.true_distance_m < hi).map(|e| e.distance_rel),
        )
    }

    pub(crate) fn relative_speed_error(&self) -> Option<(f64, f64)> {
        percentiles(self.errors.iter().filter_map(|e| e.relative_speed_abs_mps))
    }

    pub(crate) fn lateral_error(&self) -> Option<(f64, f64)> {
        percentiles(self.errors.iter().map(|e| e.lateral_abs_m))
    }
}

fn percentiles(values: impl Iterator<Item = f64>) -> Option<(f64, f64)> {
    let mut v: Vec<f64> = values.collect();
    if v.is_empty() {
        return None;
    }
    v.sort_by(f64::total_cmp);
    let at = |q: f64| v[((v.len() - 1) as f64 * q).round() as usize];
    Some((at(0.5), at(0.9)))
}

/// Runs one scenario (for at most `max_seconds` simulated) and scores every frame of the
/// detector `make` builds for its cameras.
pub(crate) fn evaluate_scenario<'a>(
    scenario: Scenario,
    seed: u64,
    settings: &SimSettings,
    max_seconds: f64,
    tally: &mut Tally,
    make: &mut dyn FnMut(&Cameras) -> crate::error::Result<Box<dyn FrameDetector + 'a>>,
) -> crate::error::Result<()> {
    let mut world = World::new(scenario, seed, settings.physics_hz);
    let mut cameras = Cameras::new(settings, &world);
    let mut detector = make(&cameras)?;
    let every = (settings.physics_hz as f64 / settings.rates_hz.camera).round().max(1.0) as u64;
    let last_step = (max_seconds * settings.physics_hz as f64) as u64;
    while world.ended().is_none() && world.step_count() <= last_step {
        if world.step_count().is_multiple_of(every) {
            let vis = cameras.draw(&world);
            let truth = ground_truth(&world, &vis);
            let dets = detector.frame(&cameras, world.time_ns())?;
            let ego = world.ego_state();
            let view = RoadView::new(world.road(), ego.position_in_world_m, ego.yaw_in_world_rad);
            tally.add_frame(&dets, &truth.objects, (60.0, 0.5), &view);
        }
        world.step(EgoInput::Follow);
    }
    tally.unanswered_frames += detector.unanswered();
    Ok(())
}

/// The scenarios to score: `names` (built-in or files), then `count` generated ones of
/// `family` (the sweep's, with `seed`); none at all: the standard set.
pub fn scenarios(
    names: &[String],
    family: Option<super::sweep::families::Family>,
    count: usize,
    seed: u64,
) -> Result<Vec<Scenario>, slipstream_contract::config::ConfigError> {
    let mut out: Vec<Scenario> = names
        .iter()
        .map(|n| Scenario::find(n).and_then(|s| s.one_ego("slipstream eval detect")))
        .collect::<Result<_, _>>()?;
    if let Some(f) = family {
        for j in 0..count {
            out.push(super::sweep::families::nth(f, seed, j).parse()?);
        }
    }
    if out.is_empty() {
        out = standard().iter().map(|n| Scenario::find(n)).collect::<Result<_, _>>()?;
    }
    Ok(out)
}

/// The standard scenarios for detection scores: every built-in one.
pub fn standard() -> Vec<String> {
    slipstream_sim::scenario::BUILT_IN.iter().map(|(name, _)| name.to_string()).collect()
}

/// Scores per scenario and over all, as `slipstream eval detect` prints them.
#[derive(Debug, Clone, Serialize)]
pub struct DetectReport {
    pub command: String,
    /// A detector of the user's own under test (`--detector`); None: slipstream-detect's.
    pub own: Option<ForeignNode>,
    /// Frames the detector did not answer in time (scored as frames without detections).
    pub unanswered_frames: u64,
    /// With `--frames`: the encoding the frames went through and its cost.
    pub frames_through: Option<LinkCost>,
    pub scenarios: Vec<ScenarioScore>,
    pub overall: ScenarioScore,
    /// The lateral error 40-200 m ahead by range band and bend ([`bend_lateral`]).
    pub lateral_in_bends: Vec<LateralCell>,
    /// The error of the place across the road, the same way: what the ACC's in-lane
    /// probability reads (config/acc.json5, lane.offset_sigma_m).
    pub across_in_bends: Vec<LateralCell>,
}

#[derive(Debug, Clone, Serialize)]
pub struct ScenarioScore {
    pub scenario: String,
    pub frames: u64,
    pub detections: u64,
    pub precision: f64,
    pub recall: f64,
    /// Vehicles within 60 m and at least half visible: how many, how many found.
    pub eligible: u64,
    pub found: u64,
    /// Beyond 60 m to 150 m (cars, vans) or 200 m (trucks), in full view: recall, how many,
    /// how many found.
    pub far_recall: Option<f64>,
    pub far_eligible: u64,
    pub far_found: u64,
    /// Per range band "lo-hi m": (median, p90) of |distance error| / true distance.
    pub distance_error: Vec<(String, Option<(f64, f64)>)>,
    /// (median, p90) of |lateral error|, metres.
    pub lateral_error_m: Option<(f64, f64)>,
    /// (median, p90) of |relative speed error|, m/s.
    pub relative_speed_error_mps: Option<(f64, f64)>,
    pub id_switches: u64,
    pub brake_lights: BrakeLightCounts,
}

impl ScenarioScore {
    pub(crate) fn from_tally(scenario: &str, t: &Tally) -> ScenarioScore {
        ScenarioScore {
            scenario: scenario.to_string(),
            frames: t.frames,
            detections: t.detections,
            precision: t.precision(),
            recall: t.recall(),
            eligible: t.eligible,
            found: t.eligible_found,
            far_recall: t.far_recall(),
            far_eligible: t.far_eligible,
            far_found: t.far_found,
            distance_error: RANGES_M
                .iter()
                .map(|&(lo, hi)| {
                    let band = if hi.is_finite() { format!("{lo:.0}-{hi:.0} m") } else { format!("{lo:.0}+ m") };
                    (band, t.distance_error(lo, hi))
                })
                .collect(),
            lateral_error_m: t.lateral_error(),
            relative_speed_error_mps: t.relative_speed_error(),
            id_switches: t.id_switches,
            brake_lights: t.brake_lights,
        }
    }
}

/// Evaluates `scenarios` (each for at most `seconds` simulated) with the cameras of `settings`
/// and the detector of `detect`; progress on stderr.
pub fn evaluate(
    scenarios: Vec<Scenario>,
    seconds: f64,
    (settings, detect): (&SimSettings, &DetectSettings),
    mut codec: Option<LinkCodec>,
    own: Option<&ForeignNode>,
) -> crate::error::Result<DetectReport> {
    let logs = std::env::temp_dir().join(format!("slipstream-eval-detect-{}", std::process::id()));
    let mut overall = Tally::default();
    let mut scores = Vec::new();
    let total = scenarios.len();
    for (i, scenario) in scenarios.into_iter().enumerate() {
        let seed = scenario.seed;
        let mut t = Tally::default();
        let started = std::time::Instant::now();
        let name = scenario.name.clone();
        let mut codec = codec.as_mut();
        let mut make = |cameras: &Cameras| -> crate::error::Result<Box<dyn FrameDetector + '_>> {
            match own {
                None => Ok(Box::new(Ours::new(cameras, detect, codec.take()))),
                Some(node) => Ok(Box::new(super::detect_remote::Yours::start(node, cameras, &logs.join(&name))?)),
            }
        };
        evaluate_scenario(scenario, seed, settings, seconds, &mut t, &mut make)?;
        eprintln!("[{}/{total}] {name}: {} frames in {:.1} s", i + 1, t.frames, started.elapsed().as_secs_f64());
        scores.push(ScenarioScore::from_tally(&name, &t));
        overall.merge(t);
    }
    let command = std::env::args().collect::<Vec<_>>().join(" ");
    let frames_through = codec.map(|c| c.cost());
    let lateral_in_bends =
        bend_lateral::table(overall.errors.iter().map(|e| (e.true_distance_m, e.bend_radius_m, e.lateral_signed_m)));
    let across_in_bends =
        bend_lateral::table(overall.errors.iter().map(|e| (e.true_distance_m, e.bend_radius_m, e.across_signed_m)));
    Ok(DetectReport {
        command,
        own: own.cloned(),
        unanswered_frames: overall.unanswered_frames,
        frames_through,
        scenarios: scores,
        overall: ScenarioScore::from_tally("all", &overall),
        lateral_in_bends,
        across_in_bends,
    })
}

impl Tally {
    pub(crate) fn merge(&mut self, other: Tally) {
        self.frames += other.frames;
        self.unanswered_frames += other.unanswered_frames;
        self.detections += other.detections;
        self.true_positives += other.true_positives;
        self.eligible += other.eligible;
        self.eligible_found += other.eligible_found;
        self.far_eligible += other.far_eligible;
        self.far_found += other.far_found;
        self.errors.extend(other.errors);
        self.id_switches += other.id_switches;
        self.brake_lights.merge(other.brake_lights);
    }
}

/// The report as markdown.
pub fn markdown(report: &DetectReport) -> String {
    let pct =
        |e: Option<(f64, f64)>| e.map_or("-".to_string(), |(m, p)| format!("{:.1}% / {:.1}%", m * 100.0, p * 100.0));
    let mut s = match &report.own {
        Some(node) => format!(
            "Detector: {} (frames over the bus; {} left unanswered)\n\n",
            node.command_line(),
            report.unanswered_frames
        ),
        None => "Detector: slipstream-detect (in process)\n\n".to_string(),
    };
    s.push_str(
        "| scenario | frames | precision | recall to 60 m (found/eligible) | recall 60-150/200 m, full view | dist. err. 0-20 m | 20-40 m | 40-60 m | 60-150 m | 150+ m | lateral err. m | rel. speed err. m/s | id switches | brake lights: lit seen lit, unlit seen lit |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    for r in report.scenarios.iter().chain(std::iter::once(&report.overall)) {
        s.push_str(&format!(
            "| {} | {} | {:.3} | {:.3} ({}/{}) | {} | {} | {} | {} | {} | {} | {} | {} | {} | {}/{}, {}/{} |\n",
            r.scenario,
            r.frames,
            r.precision,
            r.recall,
            r.found,
            r.eligible,
            r.far_recall.map_or("-".into(), |f| format!("{f:.3} ({}/{})", r.far_found, r.far_eligible)),
            pct(r.distance_error[0].1),
            pct(r.distance_error[1].1),
            pct(r.distance_error[2].1),
            pct(r.distance_error[3].1),
            pct(r.distance_error[4].1),
            r.lateral_error_m.map_or("-".into(), |(m, p)| format!("{m:.2} / {p:.2}")),
            r.relative_speed_error_mps.map_or("-".into(), |(m, p)| format!("{m:.2} / {p:.2}")),
            r.id_switches,
            r.brake_lights.lit_seen,
            r.brake_lights.lit,
            r.brake_lights.unlit_seen_lit,
            r.brake_lights.unlit,
        ));
    }
    s.push_str("\nErrors: median / p90 over matched detections (relative speed: tracks seen twice or more).\n\n");
    s.push_str(&bend_lateral::markdown(
        &report.lateral_in_bends,
        "Lateral error of matched detections (ego y), metres: standard deviation (bias, count), by true distance and the tightest bend between the ego and the vehicle.\n",
    ));
    s.push_str(&bend_lateral::markdown(
        &report.across_in_bends,
        "Error of the place across the road (each point projected on the road's map where it falls: the range's error counts too in a bend), metres, the same way.\n",
    ));
    if let Some(c) = &report.frames_through {
        let quality = if c.encoding == "jpeg" { format!(" at quality {}", c.jpeg_quality) } else { String::new() };
        s.push_str(&format!(
            "Frames through {}{quality}: {} frames (both cameras), {:.0} bytes a frame (p90 {:.0}), {:.1}x fewer than raw, encode {:.2} ms, decode {:.2} ms (medians).\n",
            c.encoding, c.frames, c.bytes_per_frame, c.bytes_p90, c.ratio, c.encode_ms, c.decode_ms
        ));
    }
    s
}

/// The detector on frames the simulator renders: distances, offsets, colours, noise.
#[cfg(test)]
mod rendered {
    use slipstream_contract::msg::{ImageEncoding, ObjectClass};
    use slipstream_perception::{DetectSettings, Detector, DetectorParams, FrameDetection};
    use slipstream_sim::ground_truth;
    use slipstream_sim::settings::SimSettings;
    use slipstream_sim::world::World;
    use slipstream_sim::Scenario;
    use slipstream_sim::SimRng;
    use slipstream_sim::{FrameLook, Renderer};

    /// Renders the start of a one-off scenario and runs the detector on it.
    fn detect_in(
        traffic: &str,
        noise: f64,
        look: FrameLook,
    ) -> (Vec<FrameDetection>, slipstream_contract::msg::GroundTruthObjects) {
        let text = format!(
            "{{ name: 't', duration_s: 10, variation: {{ gap_m: 0, speed_mps: 0 }}, ego: {{ lane: 1, speed_mps: 0 }}, traffic: [{traffic}] }}"
        );
        let world = World::new(Scenario::parse(&text, "test").unwrap(), 1, 100);
        let info = SimSettings::default().camera_info(ImageEncoding::Rgb8);
        let mut renderer = Renderer::new(&info, noise, &mut SimRng::new(3));
        let mut rgb = vec![0; renderer.frame_len()];
        let vis = renderer.render(world.road(), world.ego(), world.vehicles(), look, &mut rgb);
        (Detector::new(&info, DetectorParams::default()).detect(&rgb), ground_truth(&world, &vis))
    }

    #[test]
    fn an_empty_road_gives_no_detection() {
        assert!(detect_in("", 0.0, FrameLook::PLAIN).0.is_empty());
        assert!(detect_in("", 4.0, FrameLook { brightness: 0.85, noise_offset: 77 }).0.is_empty());
    }

    #[test]
    fn a_car_ahead_is_found_at_its_distance_and_offset() {
        for (lane, gap, d_tol) in [(1, 15.0, 0.03), (1, 35.0, 0.03), (0, 25.0, 0.03), (2, 50.0, 0.05)] {
            let (dets, truth) = detect_in(
                &format!("{{ lane: {lane}, gap_m: {gap}, speed_mps: 0, color: [200, 30, 35] }}"),
                0.0,
                FrameLook::PLAIN,
            );
            let o = &truth.objects[0];
            assert_eq!(dets.len(), 1, "lane {lane} gap {gap}: {dets:?}");
            let d = dets[0];
            let x = o.position_in_ego_m[0];
            assert!((d.distance_m - x).abs() / x < d_tol, "lane {lane}: distance {:.2} vs true {x:.2}", d.distance_m);
            assert!(
                (d.lateral_offset_m - o.position_in_ego_m[1]).abs() < 0.4,
                "lateral {:.2} vs {:?}",
                d.lateral_offset_m,
                o.position_in_ego_m
            );
            assert_eq!(d.class, ObjectClass::Car);
            assert!(d.bbox.iou(&o.bbox.unwrap()) > 0.5, "{:?} vs {:?}", d.bbox, o.bbox);
        }
    }

    /// The contact edge lies between pixel rows (anti-aliased shadows, located to a fraction
    /// of a row): the distance follows a gap growing by less than a row's worth at a time
    /// instead of stepping by whole rows (one row is ~2.4 m at 40 m, ~5 m at 60 m).
    #[test]
    fn range_follows_the_gap_between_pixel_rows() {
        let mut errors = Vec::new();
        let mut gap = 20.0;
        while gap < 70.0 {
            let (dets, truth) = detect_in(
                &format!("{{ lane: 1, gap_m: {gap}, speed_mps: 0, color: [200, 30, 35] }}"),
                0.0,
                FrameLook::PLAIN,
            );
            let x = truth.objects[0].position_in_ego_m[0];
            let d = dets.first().unwrap_or_else(|| panic!("gap {gap}: no detection")).distance_m;
            errors.push((x, (d - x) / x));
            gap += 0.61;
        }
        let worst =
            |lo: f64, hi: f64| errors.iter().filter(|e| e.0 >= lo && e.0 < hi).map(|e| e.1.abs()).fold(0.0, f64::max);
        assert!(worst(20.0, 58.0) < 0.012, "to 58 m: {errors:?}");
        assert!(worst(58.0, 75.0) < 0.04, "58-75 m: {errors:?}");
    }

    /// A motorcycle ~130 m ahead through the narrow camera: its body (8 columns) ends 4 rows
    /// above its rear tyre (4 columns, with its shadow), where it meets the road. Joined as a
    /// far car's wheels, the body's two sides read the range from the body's lower edge, 30%
    /// long, which in a bend puts a motorcycle of the next lane into the ego's. The pixels are
    /// those of such a frame (bend-neighbours-0667 of `eval sweep --seed 1`).
    #[test]
    fn a_far_motorcycle_is_ranged_at_its_tyre_not_at_its_body() {
        const PATCH: [&str; 21] = [
            "176 177 176 176 177 46 46 46 46 33 177 177 177 177 176 177",
            "177 177 176 177 177 46 46 45 46 33 177 177 177 177 177 177",
            "177 177 178 178 177 46 46 46 46 32 178 178 178 178 177 178",
            "81 81 81 81 81 46 46 46 46 33 81 81 81 81 82 81",
            "81 81 81 81 38 38 38 38 38 38 38 81 81 81 81 81",
            "81 82 81 81 38 38 38 38 38 38 38 81 81 81 81 81",
            "81 81 81 81 38 38 38 38 38 38 38 81 82 81 81 81",
            "81 81 81 82 38 38 38 38 38 38 38 81 81 81 81 81",
            "82 81 81 82 38 38 38 38 37 38 38 82 81 82 82 82",
            "81 81 81 81 46 46 46 46 46 46 32 32 81 81 81 81",
            "81 81 81 81 46 103 103 103 46 46 33 33 81 81 81 81",
            "81 81 82 81 46 46 47 46 46 46 33 33 82 81 82 81",
            "81 81 81 81 46 46 15 15 45 46 32 32 81 81 81 81",
            "81 81 81 81 46 46 16 16 46 46 32 33 81 81 81 81",
            "81 81 81 81 46 46 16 16 46 46 33 32 81 81 81 81",
            "81 81 81 81 46 47 16 16 46 46 33 33 81 81 81 81",
            "81 81 81 81 46 45 16 15 46 46 33 32 81 81 81 81",
            "81 81 81 82 81 81 16 15 11 11 81 81 81 81 81 81",
            "81 81 81 81 81 81 16 16 11 11 81 81 81 81 81 81",
            "80 81 81 81 88 104 16 16 11 11 82 81 81 81 81 81",
            "76 70 67 67 68 68 16 16 10 10 68 67 67 68 73 79",
        ];
        let text = "{ name: 't', duration_s: 10, seed: 3, variation: { gap_m: 0, speed_mps: 0 }, ego: { lane: 1, speed_mps: 0 }, traffic: [] }";
        let world = World::new(Scenario::parse(text, "test").unwrap(), 3, 100);
        let mut cameras = slipstream_sim::Cameras::new(&SimSettings::default(), &world);
        cameras.draw(&world);
        let info = cameras.narrow_info().unwrap().clone();
        let mut narrow = cameras.narrow_rgb().unwrap().to_vec();
        let (w, first_row, first_col) = (info.width as usize, 126, 764);
        for (dv, row) in PATCH.iter().enumerate() {
            for (du, grey) in row.split(' ').enumerate() {
                let at = ((first_row + dv) * w + first_col + du) * 3;
                narrow[at..at + 3].fill(grey.parse().unwrap());
            }
        }
        // Where the tyre meets the road: the lower edge of the patch's last row.
        let camera = slipstream_perception::CameraModel::new(&info);
        let tyre = camera.ground_point((first_col + 8) as f64, (first_row + PATCH.len()) as f64).unwrap().x;
        let mut rig =
            slipstream_perception::CameraRig::new(cameras.front.info(), Some(&info), &DetectSettings::default());
        for d in rig.detect(&cameras.front.rgb, Some(&narrow)) {
            assert!((d.distance_m - tyre).abs() < 0.1 * tyre, "{:.1} m, the tyre at {tyre:.1} m: {d:?}", d.distance_m);
        }
    }

    /// Through the narrow camera a vehicle's range follows it to a few centimetres at 40-48 m
    /// (a row is ~0.8 m there), a motorcycle's too. Its rear tyre stands at its rear and ends
    /// in the band's lowest row with a hard edge; counted in, it held the range while the
    /// band's edge moved and then let it jump by up to 0.11 m at each row, a step the ACC's
    /// estimator read as the lead braking.
    #[test]
    fn narrow_camera_range_moves_with_a_vehicle_without_steps() {
        for class in ["motorcycle", "car"] {
            let mut errors = Vec::new();
            let mut gap = 36.5;
            while gap < 44.5 {
                let (dets, truth) =
                    rig_detect_in(&format!("{{ lane: 1, gap_m: {gap}, speed_mps: 0, class: '{class}' }}"), 0.0);
                let x = truth.objects[0].position_in_ego_m[0];
                let d = dets.iter().find(|d| d.lateral_offset_m.abs() < 1.0);
                errors.push((x, d.map(|d| d.distance_m - x)));
                gap += 0.05;
            }
            let worst = errors.iter().map(|e| e.1.map_or(f64::INFINITY, f64::abs)).fold(0.0, f64::max);
            assert!(worst < 0.03, "{class}: worst {worst:.3} m in {errors:?}");
        }
    }

    #[test]
    fn colours_brightness_and_noise_do_not_break_it() {
        let colours = [[25, 25, 28], [140, 142, 148], [235, 235, 235], [20, 110, 60], [84, 84, 88], [230, 170, 30]];
        for c in colours {
            for (noise, look) in [
                (0.0, FrameLook::PLAIN),
                (5.0, FrameLook { brightness: 0.8, noise_offset: 5 }),
                (5.0, FrameLook { brightness: 1.15, noise_offset: 999 }),
            ] {
                let traffic = format!("{{ lane: 1, gap_m: 30, speed_mps: 0, color: {c:?} }}, {{ lane: 0, gap_m: 12, speed_mps: 0, class: 'van', color: {c:?} }}");
                let (dets, truth) = detect_in(&traffic, noise, look);
                assert_eq!(dets.len(), 2, "colour {c:?} noise {noise} {look:?}: {dets:?}");
                for o in &truth.objects {
                    let x = o.position_in_ego_m[0];
                    let found = dets.iter().find(|d| d.bbox.iou(o.bbox.as_ref().unwrap()) > 0.3);
                    let d = found.unwrap_or_else(|| panic!("colour {c:?}: vehicle {} not found in {dets:?}", o.id));
                    assert!((d.distance_m - x).abs() / x < 0.05, "colour {c:?}: {:.2} vs {x:.2}", d.distance_m);
                }
            }
        }
    }

    /// A vehicle cut by the image's side (being passed) is placed by its measured inner side
    /// and its class's width: still in its own lane, not half a lane nearer (the visible part's
    /// centre put a truck 7 m ahead in the next lane at -2.7 m against -3.5 m true). Swept from
    /// 1 to 20 m ahead in the lanes either side; every box cut by the side counts.
    #[test]
    fn a_vehicle_cut_by_the_image_side_keeps_its_lane() {
        for (vehicle, side) in [("lane: 0, class: 'truck'", -1.0), ("lane: 2, class: 'van'", 1.0), ("lane: 0", -1.0)] {
            let mut cut = Vec::new();
            for gap in 1..=20 {
                let (dets, truth) =
                    detect_in(&format!("{{ {vehicle}, gap_m: {gap}, speed_mps: 0 }}"), 0.0, FrameLook::PLAIN);
                let y = truth.objects[0].position_in_ego_m[1];
                for d in dets.iter().filter(|d| d.bbox.u_min_px <= 0.0 || d.bbox.u_max_px >= 639.0) {
                    cut.push((gap, d.lateral_offset_m, y));
                }
            }
            assert!(!cut.is_empty(), "{vehicle}: never seen cut by the side");
            // Never into the ego's lane; from 4 m ahead within 0.6 m (closer, the band seen can
            // be a sliver of the far side, which lands the vehicle farther out: the safe side).
            for &(gap, lateral, y) in &cut {
                let what = format!("{vehicle} {gap} m ahead: lateral {lateral:.2} m against {y:.2} m");
                assert!(side * lateral > 2.5, "{what}");
                assert!(gap < 4 || (lateral - y).abs() < 0.6, "{what}");
            }
        }
    }

    /// A noisy camera (12 levels of noise per channel, as in low light): a car, a van and a
    /// truck at 15-140 m in the ego's lane and the next are each found within 3% of their
    /// distance, and nothing else is. Thresholded as it was, the noise broke the contact bands
    /// up and every vehicle's top was lost in it: two in three were missed within 60 m.
    #[test]
    fn vehicles_are_found_through_a_noisy_camera() {
        let (mut seen, mut found, mut ghosts) = (0, 0, Vec::new());
        for (i, class) in ["car", "van", "truck"].into_iter().enumerate() {
            for gap in [15.0, 30.0, 45.0, 60.0, 80.0, 110.0, 140.0] {
                let lane = (i % 2) as i32 + 1;
                let traffic = format!("{{ lane: {lane}, gap_m: {gap}, speed_mps: 0, class: '{class}' }}");
                let (dets, truth) = rig_detect_in(&traffic, 12.0);
                let x = truth.objects[0].position_in_ego_m[0];
                seen += 1;
                found += usize::from(dets.iter().any(|d| ((d.distance_m - x) / x).abs() < 0.03));
                ghosts.extend(
                    dets.iter().filter(|d| ((d.distance_m - x) / x).abs() >= 0.1).map(|d| (class, gap, d.distance_m)),
                );
            }
        }
        assert!(found * 10 >= seen * 9, "found {found} of {seen}");
        assert!(ghosts.is_empty(), "detections where no vehicle is (class, gap, distance): {ghosts:?}");
    }

    /// Renders both default cameras at the start of a one-off scenario and runs the camera
    /// rig (front + narrow, fused) on them.
    fn rig_detect_in(traffic: &str, noise: f64) -> (Vec<FrameDetection>, slipstream_contract::msg::GroundTruthObjects) {
        rig_detect_on("{}", traffic, noise)
    }

    /// As `rig_detect_in`, on the given road (the scenario's `road` value).
    fn rig_detect_on(
        road: &str,
        traffic: &str,
        noise: f64,
    ) -> (Vec<FrameDetection>, slipstream_contract::msg::GroundTruthObjects) {
        let text = format!(
            "{{ name: 't', duration_s: 10, seed: 3, road: {road}, variation: {{ gap_m: 0, speed_mps: 0 }}, noise: {{ camera_stddev: {noise} }}, ego: {{ lane: 1, speed_mps: 0 }}, traffic: [{traffic}] }}"
        );
        let world = World::new(Scenario::parse(&text, "test").unwrap(), 3, 100);
        let mut cameras = slipstream_sim::Cameras::new(&SimSettings::default(), &world);
        let vis = cameras.draw(&world);
        let mut rig = slipstream_perception::CameraRig::new(
            cameras.front.info(),
            cameras.narrow_info(),
            &DetectSettings::default(),
        );
        (rig.detect(&cameras.front.rgb, cameras.narrow_rgb()), ground_truth(&world, &vis))
    }

    /// Brake lights: a vehicle ahead (its driver braking from 0.2 s on) is seen with its lamps
    /// lit after half a second and unlit before, near through the front camera and far
    /// through the narrow one, for every class; a red car cruising is not braking.
    #[test]
    fn brake_lights_are_seen_lit_only_while_the_vehicle_brakes() {
        let lights_at = |class: &str, lane: i32, gap: f64, color: &str, t_s: f64| {
            let text = format!(
                "{{ name: 't', duration_s: 10, seed: 3, variation: {{ gap_m: 0, speed_mps: 0 }}, ego: {{ lane: 1, speed_mps: 20 }}, traffic: [{{ lane: {lane}, gap_m: {gap}, speed_mps: 20, class: '{class}'{color}, actions: [{{ at_s: 0.2, speed_mps: 0, accel_mps2: 4 }}] }}] }}"
            );
            let mut world = World::new(Scenario::parse(&text, "test").unwrap(), 3, 100);
            while (world.time_ns() as f64) < t_s * 1e9 {
                world.step(slipstream_sim::world::EgoInput::Cruise);
            }
            let truth = world.vehicles()[1].brake_lights;
            let mut cameras = slipstream_sim::Cameras::new(&SimSettings::default(), &world);
            cameras.draw(&world);
            let mut rig = slipstream_perception::CameraRig::new(
                cameras.front.info(),
                cameras.narrow_info(),
                &DetectSettings::default(),
            );
            let dets = rig.detect(&cameras.front.rgb, cameras.narrow_rgb());
            let what = format!("{class}{color} in lane {lane}, {gap} m, at {t_s} s");
            assert_eq!(dets.len(), 1, "{what}: {dets:?}");
            (truth, dets[0].brake_lights)
        };
        for (class, lane, gap) in [
            ("car", 1, 15.0),
            ("car", 0, 40.0),
            ("car", 1, 120.0),
            ("van", 1, 60.0),
            ("truck", 1, 150.0),
            ("motorcycle", 1, 30.0),
        ] {
            assert_eq!(lights_at(class, lane, gap, "", 0.1), (false, false), "{class} at {gap} m cruising");
            assert_eq!(lights_at(class, lane, gap, "", 0.7), (true, true), "{class} at {gap} m braking");
        }
        assert_eq!(lights_at("car", 1, 20.0, ", color: [230, 20, 20]", 0.1), (false, false), "a red car");
    }

    /// Long range through the narrow camera: cars to 150 m and trucks to 200 m, in the ego's
    /// lane and the next, are found in at least 90% of positions swept every 3.7 m, within 3%
    /// of their distance; the front camera alone stops at 80 m. Beyond ~130 m a car's contact
    /// band is thinner than a row and only its wheels are darker than the threshold: the
    /// detector joins them (without that, cars were lost from 156 m, trucks from 165 m).
    #[test]
    fn cars_to_150_m_and_trucks_to_200_m_are_found_through_the_narrow_camera() {
        for (class, from, to) in [("car", 60.0, 150.0), ("truck", 60.0, 200.0)] {
            for lane in [1, 0] {
                let (mut seen, mut found, mut errors) = (0, 0, Vec::new());
                let mut gap = from;
                while gap <= to {
                    let (dets, truth) = rig_detect_in(
                        &format!("{{ lane: {lane}, gap_m: {gap}, speed_mps: 0, class: '{class}' }}"),
                        3.0,
                    );
                    let [x, y, _] = truth.objects[0].position_in_ego_m;
                    seen += 1;
                    if let Some(d) = dets.iter().find(|d| (d.lateral_offset_m - y).abs() < 1.0) {
                        found += 1;
                        errors.push((x, (d.distance_m - x) / x));
                    }
                    gap += 3.7;
                }
                let what = format!("{class} in lane {lane}, {from}-{to} m");
                assert!(found * 10 >= seen * 9, "{what}: found {found} of {seen}: {errors:?}");
                assert!(errors.iter().all(|e| e.1.abs() < 0.03), "{what}: {errors:?}");
            }
        }
    }

    /// In a bend the vehicles ahead are turned from the line of sight: the camera sees a side
    /// beside each rear, so the dark band under them is wider than any rear, and beside the
    /// rear lies the body's overhang, not the background. Trucks, vans and cars round right
    /// and left bends of 400 m (60-150 m ahead) and 250 m (60-105 m ahead: beyond, they leave
    /// the narrow camera's view), in the ego's lane and the next, are found in at least 90% of
    /// positions within 3% of their distance and 1 m of their place across (trucks were lost
    /// from 80 m on before).
    #[test]
    fn vehicles_seen_from_the_side_in_a_bend_are_found_at_their_rear() {
        for (radius, farthest) in [(-400.0, 150.0), (400.0, 150.0), (-250.0, 105.0), (250.0, 105.0)] {
            let road = format!("{{ curves: [{{ start_m: 20, length_m: 400, radius_m: {radius} }}] }}");
            for class in ["truck", "van", "car"] {
                for lane in [1, if radius < 0.0 { 2 } else { 0 }] {
                    let (mut seen, mut found, mut missed) = (0, 0, Vec::new());
                    let mut gap = 60.0;
                    while gap <= farthest {
                        let (dets, truth) = rig_detect_on(
                            &road,
                            &format!("{{ lane: {lane}, gap_m: {gap}, speed_mps: 0, class: '{class}' }}"),
                            3.0,
                        );
                        let [x, y, _] = truth.objects[0].position_in_ego_m;
                        seen += 1;
                        let placed = |d: &&FrameDetection| {
                            (d.lateral_offset_m - y).abs() < 1.0 && ((d.distance_m - x) / x).abs() < 0.03
                        };
                        match dets.iter().find(placed) {
                            Some(_) => found += 1,
                            None => missed.push((
                                gap,
                                x,
                                y,
                                dets.iter().map(|d| (d.distance_m, d.lateral_offset_m)).collect::<Vec<_>>(),
                            )),
                        }
                        gap += 7.5;
                    }
                    let what = format!("{class} in lane {lane}, bend radius {radius} m");
                    assert!(
                        found * 10 >= seen * 9,
                        "{what}: found {found} of {seen}; missed (gap, x, y, detections): {missed:?}"
                    );
                }
            }
        }
    }

    /// At 140-160 m the shadow under a car is thinner than a row of the narrow camera: at some
    /// distances it falls between rows and the columns between the wheels end at the body's
    /// lower edge, rows above the contact. Taken with the wheels' columns that read the car
    /// 15-20% too far (181 m for 154 m in car-standing-at-150-m); the range is the wheels'.
    /// Swept in steps of a fraction of a row.
    #[test]
    fn a_far_cars_range_holds_where_its_shadow_falls_between_rows() {
        let (mut seen, mut errors) = (0, Vec::new());
        let mut gap = 140.0;
        while gap <= 160.0 {
            let (dets, truth) = rig_detect_in(&format!("{{ lane: 1, gap_m: {gap}, speed_mps: 0 }}"), 0.0);
            let x = truth.objects[0].position_in_ego_m[0];
            if let Some(d) = dets.iter().find(|d| d.lateral_offset_m.abs() < 1.0) {
                seen += 1;
                errors.push((x, (d.distance_m - x) / x));
            }
            gap += 0.5;
        }
        assert!(seen >= 40, "found at {seen} of 41 distances");
        assert!(errors.iter().all(|e| e.1.abs() < 0.03), "{errors:?}");
    }

    /// A far vehicle whose contact band touches a nearer vehicle's dark glass in the image is
    /// still found: a thin band meeting a tall dark region a step lower is split from it.
    /// approach-slower-lead at 19 s: the car 109 m ahead in the next lane, seen beside the
    /// lead's roof 37 m ahead, was lost for 0.7 s.
    #[test]
    fn a_far_car_beside_the_leads_roof_is_found() {
        let scenario = Scenario::find("approach-slower-lead").unwrap();
        let seed = scenario.seed;
        let mut world = World::new(scenario, seed, 100);
        while world.time_ns() < 19_000_000_000 {
            world.step(slipstream_sim::world::EgoInput::Follow);
        }
        let mut cameras = slipstream_sim::Cameras::new(&SimSettings::default(), &world);
        let truth = ground_truth(&world, &cameras.draw(&world));
        let mut rig = slipstream_perception::CameraRig::new(
            cameras.front.info(),
            cameras.narrow_info(),
            &DetectSettings::default(),
        );
        let dets = rig.detect(&cameras.front.rgb, cameras.narrow_rgb());
        assert_eq!(truth.objects.len(), 2);
        for o in &truth.objects {
            let [x, y, _] = o.position_in_ego_m;
            let d = dets.iter().find(|d| (d.lateral_offset_m - y).abs() < 1.0 && (d.distance_m - x).abs() < 0.03 * x);
            assert!(d.is_some(), "vehicle at {x:.1} m, {y:.1} m not found in {dets:?}");
        }
    }

    /// A motorcycle (a band a third of a car's width under a rider as tall as a car) is found at
    /// its distance and lateral offset, riding anywhere across its lane, and named a
    /// motorcycle, near through the front camera and far through the narrow one.
    #[test]
    fn a_motorcycle_is_found_and_named_across_its_lane() {
        for (lane, offset, gap) in [(1, 0.0, 12.0), (1, 1.0, 30.0), (1, -1.0, 55.0), (0, 0.8, 25.0), (1, 0.6, 90.0)] {
            let (dets, truth) = rig_detect_in(
                &format!("{{ lane: {lane}, offset_m: {offset}, gap_m: {gap}, speed_mps: 0, class: 'motorcycle' }}"),
                3.0,
            );
            let [x, y, _] = truth.objects[0].position_in_ego_m;
            let what = format!("lane {lane} offset {offset} at {x:.1} m");
            assert_eq!(dets.len(), 1, "{what}: {dets:?}");
            let d = &dets[0];
            assert!((d.distance_m - x).abs() < 0.03 * x, "{what}: distance {:.2}", d.distance_m);
            assert!((d.lateral_offset_m - y).abs() < 0.3, "{what}: lateral {:.2} vs {y:.2}", d.lateral_offset_m);
            assert_eq!(d.class, ObjectClass::Motorcycle, "{what}: {d:?}");
        }
    }
}
