//! Scenarios: the road, the controlled vehicles' starts (one `ego`, or several `egos` each in
//! a namespace of its own), scripted traffic, end conditions, randomness and noise, read from
//! JSON5 files (docs/simulator.md documents the format; scenarios/ has the built-in ones,
//! compiled into the binary so `--scenario NAME` works from anywhere).

use std::path::Path;

use serde::Deserialize;

use slipstream_contract::config::{parse_json5, ConfigError, Invalid};
use slipstream_contract::msg::ObjectClass;
use slipstream_model::road::RoadSpec;
use slipstream_model::vehicle::VehicleParams;

/// The scenarios shipped in scenarios/, by name.
pub const BUILT_IN: &[(&str, &str)] = &[
    ("steady-follow", include_str!("../../../scenarios/steady-follow.json5")),
    ("approach-slower-lead", include_str!("../../../scenarios/approach-slower-lead.json5")),
    ("lead-brakes-to-stop", include_str!("../../../scenarios/lead-brakes-to-stop.json5")),
    ("lead-brakes-hard", include_str!("../../../scenarios/lead-brakes-hard.json5")),
    ("stop-and-go", include_str!("../../../scenarios/stop-and-go.json5")),
    ("cut-in", include_str!("../../../scenarios/cut-in.json5")),
    ("cut-out-revealing-stopped-car", include_str!("../../../scenarios/cut-out-revealing-stopped-car.json5")),
    ("busy-traffic", include_str!("../../../scenarios/busy-traffic.json5")),
    ("curve-follow", include_str!("../../../scenarios/curve-follow.json5")),
    ("stopped-car-on-shoulder", include_str!("../../../scenarios/stopped-car-on-shoulder.json5")),
    ("bend-with-stopped-cars", include_str!("../../../scenarios/bend-with-stopped-cars.json5")),
    ("lane-ends-at-bend", include_str!("../../../scenarios/lane-ends-at-bend.json5")),
    ("bend-stopped-car-in-lane", include_str!("../../../scenarios/bend-stopped-car-in-lane.json5")),
    ("passing-trucks", include_str!("../../../scenarios/passing-trucks.json5")),
    ("truck-reveals-stopped-car", include_str!("../../../scenarios/truck-reveals-stopped-car.json5")),
    ("car-standing-at-150-m", include_str!("../../../scenarios/car-standing-at-150-m.json5")),
    ("motorcycles", include_str!("../../../scenarios/motorcycles.json5")),
    ("open-road", include_str!("../../../scenarios/open-road.json5")),
];

/// The built-in scenarios with several controlled vehicles (platoons), by name: found by
/// `--scenario NAME` like the others, and kept out of [`BUILT_IN`], the suites a single ego's
/// detector and controller are judged on.
pub const SEVERAL_EGOS: &[(&str, &str)] = &[
    ("platoon-8", include_str!("../../../scenarios/platoon-8.json5")),
    ("platoon-8-hard-brake", include_str!("../../../scenarios/platoon-8-hard-brake.json5")),
    ("platoon-8-stop-and-go", include_str!("../../../scenarios/platoon-8-stop-and-go.json5")),
];

/// How far beyond its lane's edge a vehicle may be placed (`offset_m`): a shoulder's width.
pub(crate) const MAX_SHOULDER_M: f64 = 3.0;

/// Controlled vehicles one scenario may have: each costs a camera (or two) per frame and a
/// detector and controller process.
pub(crate) const MAX_EGOS: usize = 32;

/// The smallest bumper-to-bumper gap between two egos starting in one lane: bodies placed
/// closer touch at once.
pub(crate) const MIN_START_GAP_M: f64 = 2.0;

const FIX: &str = "see docs/simulator.md (scenario format) for every field and its allowed values";

/// Vehicle class as written in scenario files.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ClassSpec {
    #[default]
    Car,
    Van,
    Truck,
    Motorcycle,
}

impl From<ClassSpec> for ObjectClass {
    fn from(c: ClassSpec) -> ObjectClass {
        match c {
            ClassSpec::Car => ObjectClass::Car,
            ClassSpec::Van => ObjectClass::Van,
            ClassSpec::Truck => ObjectClass::Truck,
            ClassSpec::Motorcycle => ObjectClass::Motorcycle,
        }
    }
}

fn yes() -> bool {
    true
}

/// A scenario file.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Scenario {
    pub name: String,
    #[serde(default)]
    pub description: String,
    /// Simulated seconds until the scenario ends (if nothing ends it earlier).
    pub duration_s: f64,
    /// Drives every random choice; `--seed` overrides it.
    #[serde(default)]
    pub seed: u64,
    #[serde(default)]
    pub road: RoadSpec,
    /// The one controlled vehicle, as a file gives it; [`Scenario::parse`] moves it into
    /// `egos`, so code reads [`Scenario::ego`] and [`Scenario::egos`] only.
    #[serde(default, rename = "ego")]
    single_ego: Option<EgoSpec>,
    /// The controlled vehicles (at least one after parsing), each with its namespace. The
    /// first is "the ego": scripted traffic is placed around it and reacts to it.
    #[serde(default)]
    egos: Vec<EgoSpec>,
    #[serde(default)]
    pub traffic: Vec<TrafficSpec>,
    #[serde(default)]
    pub random_traffic: Option<RandomTraffic>,
    #[serde(default)]
    pub end: EndSpec,
    #[serde(default)]
    pub variation: Variation,
    #[serde(default)]
    pub noise: NoiseSpec,
    /// What a controller must achieve here beyond the standard aims (`slipstream eval acc`
    /// judges it).
    #[serde(default)]
    pub expect: Expect,
}

/// A scenario's own aims for the controller under test.
#[derive(Debug, Clone, PartialEq, Default, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Expect {
    /// The smallest bumper-to-bumper gap to the lead the controller keeps, metres (the
    /// standard aim: any gap above 0).
    pub min_gap_m: Option<f64>,
    /// The most braking the scenario's own physics warrants: `none` (the ego's lane stays
    /// clear: braking beyond 1 m/s2 at speed is phantom braking whatever the judge reads from
    /// the ground truth), `comfort` (any emergency is unwarranted) or `emergency`; absent: the
    /// judge's reading of the ground truth alone. Generated scenarios (`eval sweep`) declare it.
    pub braking: Option<Warranted>,
}

/// How much braking a scenario warrants (its `expect.braking`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Warranted {
    /// Nothing comes into the ego's lane near enough to brake for.
    None,
    /// Comfort braking suffices for everything that does.
    Comfort,
    /// An emergency may be needed.
    Emergency,
}

#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EgoSpec {
    /// Where this vehicle's topics live under the run's namespace (`car1`: car1/vehicle/speed,
    /// car1/camera/front, car1/vehicle/control, ...), and its nodes with them. None: the run's
    /// namespace itself (one ego). Every ego of several has one of its own.
    #[serde(default)]
    pub namespace: Option<String>,
    pub lane: u32,
    /// Start position of the rear axle along the road.
    #[serde(default = "EgoSpec::default_s")]
    pub s_m: f64,
    pub speed_mps: f64,
    /// The cruise speed a controller is set to (`slipstream eval acc` sets the ACC to it);
    /// default: the start speed.
    #[serde(default)]
    pub set_speed_mps: Option<f64>,
    /// The time gap a controller keeps to the lead (`slipstream up` and `eval acc` set the ACC
    /// to it), 0.8 to 3.0 s; default: the ACC's own setting.
    #[serde(default)]
    pub time_gap_s: Option<f64>,
    #[serde(default)]
    pub class: ClassSpec,
    /// The simulator steers the ego along its lane; vehicle/control's steer adds to it.
    #[serde(default = "yes")]
    pub lane_keeping: bool,
    #[serde(default)]
    pub color: Option<[u8; 3]>,
}

impl EgoSpec {
    fn default_s() -> f64 {
        50.0
    }

    /// The cruise speed a controller is set to: `set_speed_mps`, else the start speed.
    pub fn controller_set_speed_mps(&self) -> f64 {
        self.set_speed_mps.unwrap_or(self.speed_mps)
    }
}

/// One scripted traffic vehicle.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TrafficSpec {
    #[serde(default)]
    pub class: ClassSpec,
    pub lane: u32,
    /// Bumper-to-bumper distance ahead of the ego at the start (negative: behind it).
    pub gap_m: f64,
    pub speed_mps: f64,
    /// Where across its lane it drives: metres from the lane's centre, positive left. Beyond
    /// the lane's half width it straddles the line; beyond the road's edge it is on the
    /// shoulder (a stopped car there, say).
    #[serde(default)]
    pub offset_m: f64,
    #[serde(default)]
    pub color: Option<[u8; 3]>,
    /// Slow down for the vehicle ahead in its lane (never for one behind).
    #[serde(default = "yes")]
    pub follow: bool,
    #[serde(default)]
    pub actions: Vec<Action>,
}

/// A change of target speed and/or lane, at a time or when the ego comes close.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Action {
    /// Simulated time at which the action starts.
    #[serde(default)]
    pub at_s: Option<f64>,
    /// Or: start when the bumper-to-bumper distance to the ego falls below this.
    #[serde(default)]
    pub when_gap_m: Option<f64>,
    /// New target speed...
    #[serde(default)]
    pub speed_mps: Option<f64>,
    /// ...reached at this acceleration or deceleration.
    #[serde(default = "Action::default_accel")]
    pub accel_mps2: f64,
    /// New lane...
    #[serde(default)]
    pub lane: Option<u32>,
    /// ...and/or new place across it (as the vehicle's `offset_m`)...
    #[serde(default)]
    pub offset_m: Option<f64>,
    /// ...reached over this long.
    #[serde(default = "Action::default_duration")]
    pub duration_s: f64,
}

impl Action {
    fn default_accel() -> f64 {
        2.0
    }
    fn default_duration() -> f64 {
        4.0
    }
}

/// Traffic placed at random (from the seed) around the ego.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RandomTraffic {
    pub count: u32,
    /// Lanes to use; empty means every lane.
    #[serde(default)]
    pub lanes: Vec<u32>,
    /// Range of start positions relative to the ego's, along the road.
    #[serde(default = "RandomTraffic::default_range")]
    pub range_m: [f64; 2],
    pub speed_mps: [f64; 2],
    /// Smallest distance between two vehicles' starts in one lane.
    #[serde(default = "RandomTraffic::default_spacing")]
    pub min_spacing_m: f64,
    /// Mean time between lane changes of one vehicle; none when absent.
    #[serde(default)]
    pub lane_change_every_s: Option<f64>,
    /// Share of vans and trucks.
    #[serde(default)]
    pub van_share: f64,
    #[serde(default)]
    pub truck_share: f64,
}

impl RandomTraffic {
    fn default_range() -> [f64; 2] {
        [-80.0, 300.0]
    }
    fn default_spacing() -> f64 {
        30.0
    }
}

#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct EndSpec {
    /// End (unsuccessfully) at the ego's first collision.
    pub on_collision: bool,
    /// End (successfully) when the ego has travelled this far.
    pub ego_distance_m: Option<f64>,
}

impl Default for EndSpec {
    fn default() -> Self {
        EndSpec { on_collision: true, ego_distance_m: None }
    }
}

/// Small random variations of the start, so one scenario covers a family of runs.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Variation {
    /// Each traffic vehicle's start gap varies uniformly within +-this.
    pub gap_m: f64,
    /// Each traffic vehicle's start speed varies uniformly within +-this.
    pub speed_mps: f64,
}

impl Default for Variation {
    fn default() -> Self {
        Variation { gap_m: 1.0, speed_mps: 0.3 }
    }
}

/// Sensor noise and image changes.
#[derive(Debug, Clone, PartialEq, Default, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct NoiseSpec {
    /// Standard deviation of the noise added to vehicle/speed.
    pub speed_mps: f64,
    /// Standard deviation of the noise added to each pixel channel (0-255 scale).
    pub camera_stddev: f64,
    /// Each frame's brightness is scaled by a factor drawn from 1 +- this.
    pub brightness: f64,
}

impl Scenario {
    /// A built-in scenario by name, or a file by path (anything with a `/` or ending in
    /// `.json5`).
    pub fn find(name_or_path: &str) -> Result<Scenario, ConfigError> {
        if name_or_path.contains('/') || name_or_path.ends_with(".json5") {
            return Scenario::load(Path::new(name_or_path));
        }
        let names = || BUILT_IN.iter().chain(SEVERAL_EGOS).map(|(n, _)| *n);
        match BUILT_IN.iter().chain(SEVERAL_EGOS).find(|(name, _)| *name == name_or_path) {
            Some((name, text)) => Scenario::parse(text, &format!("scenarios/{name}.json5")),
            None => Err(ConfigError::new(
                "--scenario",
                "",
                match slipstream_contract::config::closest(name_or_path, names()) {
                    Some(meant) => format!("no built-in scenario named `{name_or_path}`: did you mean `{meant}`?"),
                    None => format!("no built-in scenario named `{name_or_path}`"),
                },
                format!("use one of: {} (or a path to a .json5 file)", names().collect::<Vec<_>>().join(", ")),
            )),
        }
    }

    pub fn load(path: &Path) -> Result<Scenario, ConfigError> {
        let origin = ConfigError::file(path);
        let text = std::fs::read_to_string(path)
            .map_err(|e| ConfigError::new(&origin, "", format!("cannot read scenario: {e}"), "check the path"))?;
        Scenario::parse(&text, &origin)
    }

    /// Parses and checks scenario text; `origin` names it in errors.
    pub fn parse(text: &str, origin: &str) -> Result<Scenario, ConfigError> {
        let mut scenario: Scenario = parse_json5(text, origin, FIX)?;
        scenario.gather_egos().map_err(|i| i.at(origin))?;
        scenario.check().map_err(|i| i.at(origin))?;
        Ok(scenario)
    }

    /// The controlled vehicle traffic is placed around: the only one, or the first of `egos`.
    pub fn ego(&self) -> &EgoSpec {
        &self.egos[0]
    }

    /// This scenario for a tool that runs one ego's nodes: an error naming the scenario and
    /// what to do instead when it has several.
    pub fn one_ego(self, tool: &str) -> Result<Scenario, ConfigError> {
        if self.egos.len() == 1 {
            return Ok(self);
        }
        Err(ConfigError::new(
            "--scenario",
            "egos",
            format!("`{}` has {} controlled vehicles and {tool} runs one ego's detector and controller", self.name, self.egos.len()),
            "run it with `slipstream up`, `slipstream eval acc` or `slipstream eval platoon`, or slipstream-sim with each ego's nodes in its namespace (docs/simulator.md, \"Several controlled vehicles\"); or pick a scenario with one `ego`",
        ))
    }

    /// Every controlled vehicle, the first being [`Scenario::ego`].
    pub fn egos(&self) -> &[EgoSpec] {
        &self.egos
    }

    /// The key a field of ego `k` is named by in errors: `ego.<field>` for a file with one
    /// `ego`, `egos[k].<field>` for one with a list.
    fn ego_key(&self, k: usize, field: &str) -> String {
        if self.egos_listed() {
            format!("egos[{k}].{field}")
        } else {
            format!("ego.{field}")
        }
    }

    fn egos_listed(&self) -> bool {
        self.single_ego.is_none()
    }

    /// `ego` or `egos`, exactly one of them, into `egos`.
    fn gather_egos(&mut self) -> Result<(), Invalid> {
        match (&self.single_ego, self.egos.is_empty()) {
            (Some(_), false) => Invalid::err(
                "egos",
                "the file gives both `ego` and `egos`",
                "give one `ego` for a single controlled vehicle, or list every one in `egos`",
            ),
            (None, true) => Invalid::err(
                "ego",
                "no controlled vehicle",
                "give `ego: { lane, speed_mps }`, or `egos: [ { namespace, lane, s_m, speed_mps }, ... ]`",
            ),
            (Some(ego), true) => {
                self.egos = vec![ego.clone()];
                Ok(())
            }
            (None, false) => Ok(()),
        }
    }

    /// The checks serde cannot make: ranges and references between fields. The first one
    /// off.
    fn check(&self) -> Result<(), Invalid> {
        self.check_road_and_ego()?;
        for (i, t) in self.traffic.iter().enumerate() {
            self.check_traffic(i, t)?;
        }
        if let Some(r) = &self.random_traffic {
            self.check_random_traffic(r)?;
        }
        self.check_variation_and_noise()?;
        match self.expect.min_gap_m {
            Some(g) if !(g.is_finite() && (0.0..=100.0).contains(&g)) => Invalid::err(
                "expect.min_gap_m",
                format!("{g} m"),
                "give a gap of 0 to 100 m, or leave it out (any gap above 0)",
            ),
            _ => Ok(()),
        }
    }

    fn check_road_and_ego(&self) -> Result<(), Invalid> {
        if !(self.duration_s.is_finite() && self.duration_s > 0.0) {
            return Invalid::err(
                "duration_s",
                format!("{} is not a positive duration", self.duration_s),
                "give seconds > 0",
            );
        }
        if let Some(invalid) = self.road.invalid() {
            return Err(invalid);
        }
        for k in 0..self.egos.len() {
            self.check_ego(k)?;
        }
        self.check_egos_apart()
    }

    /// Controlled vehicle `k`: its lane, speeds and time gap.
    fn check_ego(&self, k: usize) -> Result<(), Invalid> {
        let (ego, lanes) = (&self.egos[k], self.road.lanes);
        let key = |field: &str| self.ego_key(k, field);
        if ego.lane >= lanes {
            return Invalid::err(
                key("lane"),
                format!("lane {} does not exist on a {lanes}-lane road", ego.lane),
                format!("lanes are numbered 0 (rightmost) to {}", lanes.saturating_sub(1)),
            );
        }
        if let Some(end) = self.road.lane_end(ego.lane) {
            return Invalid::err(
                key("lane"),
                format!("lane {} ends at {} m and the ego keeps its lane", end.lane, end.end_m),
                "start the ego in a lane that goes on; traffic in the ending lane merges",
            );
        }
        let speed_ok = |v: f64| v.is_finite() && (0.0..=70.0).contains(&v);
        if !speed_ok(ego.speed_mps) {
            return Invalid::err(key("speed_mps"), format!("{} m/s", ego.speed_mps), "use 0 to 70 m/s");
        }
        if let Some(v) = ego.set_speed_mps.filter(|v| !speed_ok(*v)) {
            return Invalid::err(key("set_speed_mps"), format!("{v} m/s"), "use 0 to 70 m/s");
        }
        if !ego.s_m.is_finite() {
            return Invalid::err(key("s_m"), format!("{}", ego.s_m), "give metres along the road");
        }
        if let Some(h) = ego.time_gap_s.filter(|h| !(0.8..=3.0).contains(h)) {
            return Invalid::err(
                key("time_gap_s"),
                format!("{h} s"),
                "use 0.8 to 3.0 s (ISO 15622 asks at least 0.8 s)",
            );
        }
        Ok(())
    }

    /// Several egos: each in a namespace of its own, none where another is.
    fn check_egos_apart(&self) -> Result<(), Invalid> {
        if self.egos.len() > MAX_EGOS {
            return Invalid::err(
                "egos",
                format!("{} controlled vehicles", self.egos.len()),
                format!("use at most {MAX_EGOS}"),
            );
        }
        if self.egos.len() == 1 {
            return Ok(());
        }
        for (k, ego) in self.egos.iter().enumerate() {
            let ns = ego.namespace.as_deref().unwrap_or("");
            if let Some(why) = namespace_problem(ns) {
                return Invalid::err(
                    self.ego_key(k, "namespace"),
                    why,
                    "give each ego a plain key of its own, such as `car1`",
                );
            }
            if let Some(j) = self.egos[..k].iter().position(|o| o.namespace == ego.namespace) {
                return Invalid::err(
                    self.ego_key(k, "namespace"),
                    format!("`{ns}` is egos[{j}]'s namespace too"),
                    "give each ego a namespace of its own: their topics would mix",
                );
            }
            if let Some(j) =
                self.egos[..k].iter().position(|o| o.lane == ego.lane && bumper_gap_m(o, ego) < MIN_START_GAP_M)
            {
                return Invalid::err(
                    self.ego_key(k, "s_m"),
                    format!("{} m in lane {} overlaps egos[{j}] (at {} m)", ego.s_m, ego.lane, self.egos[j].s_m),
                    format!("start egos in one lane at least {MIN_START_GAP_M} m apart, bumper to bumper"),
                );
            }
        }
        Ok(())
    }

    /// Scripted vehicle `i`: its lane, speed, start gap and actions.
    fn check_traffic(&self, i: usize, t: &TrafficSpec) -> Result<(), Invalid> {
        let lanes = self.road.lanes;
        let lane_fix = format!("lanes are numbered 0 (rightmost) to {}", lanes.saturating_sub(1));
        let speed_ok = |v: f64| v.is_finite() && (0.0..=70.0).contains(&v);
        let key = |field: &str| format!("traffic[{i}].{field}");
        if t.lane >= lanes {
            return Invalid::err(
                key("lane"),
                format!("lane {} does not exist on a {lanes}-lane road", t.lane),
                &lane_fix,
            );
        }
        if !speed_ok(t.speed_mps) {
            return Invalid::err(key("speed_mps"), format!("{} m/s", t.speed_mps), "use 0 to 70 m/s");
        }
        if !self.offset_ok(t.offset_m) {
            return Invalid::err(key("offset_m"), format!("{} m", t.offset_m), self.offset_fix());
        }
        if t.lane == self.ego().lane && t.gap_m.abs() < 2.0 {
            return Invalid::err(
                key("gap_m"),
                format!("{} m overlaps the ego in its lane", t.gap_m),
                "use |gap_m| >= 2",
            );
        }
        let overlaps =
            |e: &&EgoSpec| e.lane == t.lane && self.traffic_gap_to_m(t, e) < MIN_START_GAP_M + self.variation.gap_m;
        if let Some(k) = self.egos.iter().skip(1).position(|e| overlaps(&e)) {
            return Invalid::err(
                key("gap_m"),
                format!("{} m from the first ego puts it where egos[{}] starts", t.gap_m, k + 1),
                "keep scripted vehicles at least 2 m (plus variation.gap_m) from every ego, bumper to bumper",
            );
        }
        for (j, a) in t.actions.iter().enumerate() {
            let key = |field: &str| format!("traffic[{i}].actions[{j}]{field}");
            match (a.at_s, a.when_gap_m) {
                (Some(_), None) | (None, Some(_)) => {}
                _ => return Invalid::err(key(""), "needs exactly one trigger", "give either at_s or when_gap_m"),
            }
            if a.speed_mps.is_none() && a.lane.is_none() && a.offset_m.is_none() {
                return Invalid::err(key(""), "does nothing", "give speed_mps, lane, offset_m or several");
            }
            if let Some(o) = a.offset_m.filter(|o| !self.offset_ok(*o)) {
                return Invalid::err(key(".offset_m"), format!("{o} m"), self.offset_fix());
            }
            if let Some(v) = a.speed_mps.filter(|v| !speed_ok(*v)) {
                return Invalid::err(key(".speed_mps"), format!("{v} m/s"), "use 0 to 70 m/s");
            }
            if let Some(l) = a.lane.filter(|l| *l >= lanes) {
                return Invalid::err(
                    key(".lane"),
                    format!("lane {l} does not exist on a {lanes}-lane road"),
                    &lane_fix,
                );
            }
            if !(a.accel_mps2 > 0.0 && a.accel_mps2 <= 10.0) {
                return Invalid::err(key(".accel_mps2"), format!("{} m/s2", a.accel_mps2), "use (0, 10] m/s2");
            }
            if !(a.duration_s >= 0.5 && a.duration_s <= 30.0) {
                return Invalid::err(key(".duration_s"), format!("{} s", a.duration_s), "use 0.5 to 30 s");
            }
        }
        Ok(())
    }

    /// Bumper-to-bumper gap between scripted vehicle `t` (placed from the first ego by its
    /// `gap_m`) and ego `e`.
    fn traffic_gap_to_m(&self, t: &TrafficSpec, e: &EgoSpec) -> f64 {
        let ego = VehicleParams::of_class(self.ego().class.into());
        let len = VehicleParams::of_class(t.class.into()).size_m[0];
        let ego_rear = self.ego().s_m - ego.rear_overhang_m;
        let rear = if t.gap_m >= 0.0 { ego_rear + ego.size_m[0] + t.gap_m } else { ego_rear + t.gap_m - len };
        let (e_rear, e_front) = span(e);
        if rear >= e_rear {
            rear - e_front
        } else {
            e_rear - (rear + len)
        }
    }

    /// An offset across a lane: within the lane, on its lines, or up to MAX_SHOULDER_M beyond.
    fn offset_ok(&self, offset_m: f64) -> bool {
        offset_m.is_finite() && offset_m.abs() <= self.road.lane_width_m / 2.0 + MAX_SHOULDER_M
    }

    fn offset_fix(&self) -> String {
        format!(
            "use metres from the lane's centre, positive left, at most {} (half a lane plus {MAX_SHOULDER_M} m of shoulder)",
            self.road.lane_width_m / 2.0 + MAX_SHOULDER_M
        )
    }

    fn check_random_traffic(&self, r: &RandomTraffic) -> Result<(), Invalid> {
        let lanes = self.road.lanes;
        let lane_fix = format!("lanes are numbered 0 (rightmost) to {}", lanes.saturating_sub(1));
        let speed_ok = |v: f64| v.is_finite() && (0.0..=70.0).contains(&v);
        if let Some(l) = r.lanes.iter().find(|l| **l >= lanes) {
            return Invalid::err(
                "random_traffic.lanes",
                format!("lane {l} does not exist on a {lanes}-lane road"),
                &lane_fix,
            );
        }
        if r.count > 500 {
            return Invalid::err("random_traffic.count", format!("{} vehicles", r.count), "use at most 500");
        }
        if !(speed_ok(r.speed_mps[0]) && speed_ok(r.speed_mps[1]) && r.speed_mps[0] <= r.speed_mps[1]) {
            return Invalid::err(
                "random_traffic.speed_mps",
                format!("{:?}", r.speed_mps),
                "give [low, high] within 0..70 m/s",
            );
        }
        if r.range_m[0].is_nan() || r.range_m[0] >= r.range_m[1] {
            return Invalid::err(
                "random_traffic.range_m",
                format!("{:?}", r.range_m),
                "give [behind, ahead] with behind < ahead",
            );
        }
        if r.min_spacing_m.is_nan() || r.min_spacing_m < 8.0 {
            return Invalid::err("random_traffic.min_spacing_m", format!("{} m", r.min_spacing_m), "use at least 8 m");
        }
        if !(0.0..=1.0).contains(&(r.van_share + r.truck_share)) || r.van_share < 0.0 || r.truck_share < 0.0 {
            return Invalid::err("random_traffic.van_share", "shares must be >= 0 and add up to <= 1", FIX);
        }
        Ok(())
    }

    fn check_variation_and_noise(&self) -> Result<(), Invalid> {
        if let Some(d) = self.end.ego_distance_m.filter(|d| d.is_nan() || *d <= 0.0) {
            return Invalid::err("end.ego_distance_m", format!("{d} m"), "give a distance > 0");
        }
        for (key, v) in [
            ("variation.gap_m", self.variation.gap_m),
            ("variation.speed_mps", self.variation.speed_mps),
            ("noise.speed_mps", self.noise.speed_mps),
            ("noise.camera_stddev", self.noise.camera_stddev),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Invalid::err(key, format!("{v}"), "use a value >= 0");
            }
        }
        if !(0.0..0.9).contains(&self.noise.brightness) {
            return Invalid::err("noise.brightness", format!("{}", self.noise.brightness), "use 0 to 0.9");
        }
        Ok(())
    }
}

/// Why `ns` cannot be an ego's namespace, if it cannot: it is empty, or not a plain key.
fn namespace_problem(ns: &str) -> Option<String> {
    if ns.is_empty() {
        return Some("has no namespace (several egos need one each)".into());
    }
    let plain = |c: char| c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '/');
    if !ns.chars().all(plain) || ns.starts_with('/') || ns.ends_with('/') || ns.contains("//") {
        return Some(format!("`{ns}` is not a plain key (letters, digits, -, _ and / between words)"));
    }
    None
}

/// Where an ego's bumpers start along the road: (rear, front).
fn span(e: &EgoSpec) -> (f64, f64) {
    let p = VehicleParams::of_class(e.class.into());
    let rear = e.s_m - p.rear_overhang_m;
    (rear, rear + p.size_m[0])
}

/// Bumper-to-bumper gap between two egos in one lane, from their rear axles and classes.
fn bumper_gap_m(a: &EgoSpec, b: &EgoSpec) -> f64 {
    let ((a0, a1), (b0, b1)) = (span(a), span(b));
    if a0 <= b0 {
        b0 - a1
    } else {
        a0 - b1
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_mistyped_scenario_name_is_answered_with_the_one_meant() {
        let e = Scenario::find("cutin").unwrap_err().to_string();
        assert!(e.contains("did you mean `cut-in`?") && e.contains("steady-follow"), "{e}");
        let e = Scenario::find("motorway").unwrap_err().to_string();
        assert!(!e.contains("did you mean"), "{e}");
    }

    #[test]
    fn every_built_in_scenario_parses_and_is_named_after_its_file() {
        for (name, _) in BUILT_IN {
            let s = Scenario::find(name).unwrap_or_else(|e| panic!("{e}"));
            assert_eq!(&s.name, name);
            assert_eq!(s.egos().len(), 1, "{name}: the single-ego suites run it");
        }
        for (name, _) in SEVERAL_EGOS {
            let s = Scenario::find(name).unwrap_or_else(|e| panic!("{e}"));
            assert_eq!(&s.name, name);
            assert!(s.egos().len() > 1, "{name}");
            let e = s.one_ego("slipstream eval faults").unwrap_err();
            assert!(e.problem.contains("controlled vehicles") && e.fix.contains("namespace"), "{e}");
        }
    }

    #[test]
    fn errors_name_the_file_the_field_and_a_fix() {
        let base = r#"{ name: "x", duration_s: 10, ego: { lane: 1, speed_mps: 20 }, traffic: [ { lane: 1, gap_m: 30, speed_mps: 20, actions: [ { at_s: 2, lane: 5 } ] } ] }"#;
        let e = Scenario::parse(base, "my.json5").unwrap_err();
        assert_eq!((e.origin.as_str(), e.key.as_str()), ("my.json5", "traffic[0].actions[0].lane"));
        assert!(e.to_string().contains("lanes are numbered 0 (rightmost) to 2"), "{e}");

        let typo = base.replace("gap_m: 30", "gap: 30");
        let e = Scenario::parse(&typo, "my.json5").unwrap_err();
        assert!(e.problem.contains("unknown field `gap`"), "{e}");

        let no_trigger = base.replace("at_s: 2, ", "");
        let e = Scenario::parse(&no_trigger, "my.json5").unwrap_err();
        assert_eq!(e.key, "traffic[0].actions[0]");
        assert!(e.fix.contains("at_s or when_gap_m"));

        let fine = base.replace("lane: 5", "lane: 2");
        let expect = fine.replacen("ego:", "expect: { min_gap_m: -1 }, ego:", 1);
        let e = Scenario::parse(&expect, "my.json5").unwrap_err();
        assert_eq!(e.key, "expect.min_gap_m", "{e}");
        let expect = fine.replacen("ego:", "expect: { min_gap_m: 5 }, ego:", 1);
        assert_eq!(Scenario::parse(&expect, "my.json5").unwrap().expect.min_gap_m, Some(5.0));

        let off = fine.replace("lane: 1, gap_m: 30", "lane: 1, offset_m: 9, gap_m: 30");
        let e = Scenario::parse(&off, "my.json5").unwrap_err();
        assert_eq!(e.key, "traffic[0].offset_m", "{e}");
        assert!(e.fix.contains("4.75"), "{e}");

        let ends = |ends: &str| fine.replacen("ego:", &format!("road: {{ lane_ends: [{ends}] }}, ego:"), 1);
        let e = Scenario::parse(&ends("{ lane: 1, end_m: 500 }"), "my.json5").unwrap_err();
        assert_eq!(e.key, "road.lane_ends[0].lane", "{e}");
        let e = Scenario::parse(&ends("{ lane: 0, end_m: 50, taper_m: 100 }"), "my.json5").unwrap_err();
        assert_eq!(e.key, "road.lane_ends[0]", "{e}");
        let e = Scenario::parse(&ends("{ lane: 2, end_m: 500 }, { lane: 2, end_m: 900 }"), "my.json5").unwrap_err();
        assert!(e.problem.contains("ends twice"), "{e}");
        let e =
            Scenario::parse(&ends("{ lane: 2, end_m: 500 }").replace("ego: { lane: 1", "ego: { lane: 2"), "my.json5")
                .unwrap_err();
        assert_eq!(e.key, "ego.lane", "{e}");
        let ok = Scenario::parse(&ends("{ lane: 0, end_m: 500 }"), "my.json5").unwrap();
        assert_eq!(ok.road.lane_ends[0].taper_m, 120.0);

        let e = Scenario::parse("{ name: ", "my.json5").unwrap_err();
        assert!(e.problem.starts_with("not valid JSON5"), "{e}");

        let e = Scenario::find("no-such-scenario").unwrap_err();
        assert!(e.fix.contains("cut-in"), "{e}");
    }

    const TWO: &str = r#"{ name: "two", duration_s: 10, egos: [
        { namespace: "car1", lane: 1, s_m: 120, speed_mps: 20 },
        { namespace: "car2", lane: 1, s_m: 90, speed_mps: 20, time_gap_s: 2.0 } ] }"#;

    #[test]
    fn several_egos_are_listed_with_their_namespaces_and_one_ego_is_the_list_of_one() {
        let s = Scenario::parse(TWO, "two.json5").unwrap();
        assert_eq!(s.egos().len(), 2);
        assert_eq!(s.ego().namespace.as_deref(), Some("car1"));
        assert_eq!((s.egos()[1].s_m, s.egos()[1].time_gap_s), (90.0, Some(2.0)));
        let one = Scenario::find("cut-in").unwrap();
        assert_eq!((one.egos().len(), one.ego().namespace.as_deref()), (1, None));
    }

    #[test]
    fn egos_in_one_place_or_one_namespace_name_the_key_and_the_fix() {
        let err = |text: String| Scenario::parse(&text, "two.json5").unwrap_err();
        let e = err(TWO.replace("s_m: 90", "s_m: 118"));
        assert_eq!((e.origin.as_str(), e.key.as_str()), ("two.json5", "egos[1].s_m"), "{e}");
        assert!(e.problem.contains("overlaps egos[0]") && e.fix.contains("2 m apart"), "{e}");
        let e = err(TWO.replace("\"car2\"", "\"car1\""));
        assert_eq!(e.key, "egos[1].namespace", "{e}");
        assert!(e.problem.contains("egos[0]'s namespace too"), "{e}");
        let e = err(TWO.replace("namespace: \"car2\", ", ""));
        assert!(e.key == "egos[1].namespace" && e.problem.contains("no namespace"), "{e}");
        let e = err(TWO.replace("\"car2\"", "\"car/*\""));
        assert!(e.problem.contains("not a plain key"), "{e}");
        let e = err(TWO.replace("lane: 1, s_m: 90", "lane: 7, s_m: 90"));
        assert_eq!(e.key, "egos[1].lane", "{e}");
        let e = err(TWO.replace("egos: [", "ego: { lane: 1, speed_mps: 20 }, egos: ["));
        assert!(e.problem.contains("both `ego` and `egos`"), "{e}");
        let e = err(r#"{ name: "none", duration_s: 10 }"#.to_string());
        assert!(e.key == "ego" && e.fix.contains("egos"), "{e}");
        // A scripted vehicle placed from the first ego onto the second.
        let e = err(TWO.replace("] }", "], traffic: [ { lane: 1, gap_m: -30, speed_mps: 20 } ] }"));
        assert_eq!(e.key, "traffic[0].gap_m", "{e}");
        assert!(e.problem.contains("where egos[1] starts"), "{e}");
        let apart = TWO.replace("] }", "], traffic: [ { lane: 1, gap_m: -50, speed_mps: 20 } ] }");
        assert!(Scenario::parse(&apart, "two.json5").is_ok());
    }
}
