//! The simulated world: road, the controlled vehicles (egos) and traffic, stepped at a fixed
//! rate. No I/O: the node (crates/sim/src/node.rs) feeds it each ego's commands and publishes
//! what it reports. The egos are bodies 0..n (ids 0..n, the scenario's order), traffic after.

use nalgebra::{Rotation2, Vector2};

use super::driver::{pursue, Cruise, Lead, Neighbour, Observation, TrafficDriver, Wander};
use super::dynamics::{forces, Actuation};
use super::physics::{BodyId, Physics};
use super::rng::SimRng;
use super::scenario::{ClassSpec, RandomTraffic, Scenario};
use slipstream_contract::msg::{ControlCommand, ObjectClass, VehicleState};
use slipstream_model::road::Road;
use slipstream_model::vehicle::{actuate_acceleration, lag_toward, VehicleParams};

/// The (first) ego's id in ground truth and collisions; further egos are 1..n, traffic is
/// numbered after them.
pub const EGO_ID: u32 = 0;

/// Body colours traffic is painted with (unless the scenario gives one).
const PALETTE: [[u8; 3]; 10] = [
    [200, 30, 35],
    [30, 70, 160],
    [225, 225, 220],
    [25, 25, 28],
    [140, 142, 148],
    [20, 110, 60],
    [230, 170, 30],
    [110, 40, 120],
    [190, 95, 30],
    [90, 150, 200],
];

/// A vehicle as the renderer and ground truth see it, after the last step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VehicleView {
    pub id: u32,
    pub class: ObjectClass,
    pub params: VehicleParams,
    pub color: [u8; 3],
    /// Body origin: rear-axle centre on the ground.
    pub rear_axle: Vector2<f64>,
    pub yaw_rad: f64,
    pub velocity_mps: Vector2<f64>,
    pub yaw_rate_radps: f64,
    /// Road coordinates of the rear axle.
    pub s_m: f64,
    pub d_m: f64,
    pub lane: i32,
    /// Its brake lights are on: the brake pedal is pressed beyond BRAKE_LIGHT_PEDAL.
    pub brake_lights: bool,
}

/// Brake pedal (0..1) beyond which a vehicle's brake lights come on: about 0.3 m/s2 of a
/// car's 9 m/s2, so that a driver's lightest touch lights them and coasting does not.
pub(crate) const BRAKE_LIGHT_PEDAL: f64 = 0.03;

impl VehicleView {
    pub fn forward_speed_mps(&self) -> f64 {
        self.velocity_mps.dot(&Vector2::new(self.yaw_rad.cos(), self.yaw_rad.sin()))
    }

    /// Along-road positions of the rear and front bumpers.
    pub(crate) fn s_rear_m(&self) -> f64 {
        self.s_m - self.params.rear_overhang_m
    }

    pub fn s_front_m(&self) -> f64 {
        self.s_m - self.params.rear_overhang_m + self.params.size_m[0]
    }

    fn observation(&self) -> Observation {
        Observation {
            id: self.id,
            s_m: self.s_m,
            d_m: self.d_m,
            rear_axle: self.rear_axle,
            yaw_rad: self.yaw_rad,
            speed_mps: self.forward_speed_mps(),
        }
    }
}

/// Bumper-to-bumper distance between two vehicles along the road (negative: overlapping).
pub(crate) fn bumper_gap_m(a: &VehicleView, b: &VehicleView) -> f64 {
    if b.s_m >= a.s_m {
        b.s_rear_m() - a.s_front_m()
    } else {
        a.s_rear_m() - b.s_front_m()
    }
}

/// What drives the ego this step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum EgoInput {
    /// Hold the start speed in lane (before any controller has spoken).
    Cruise,
    /// Hold the start speed in lane, slowing for the vehicle ahead as traffic does (a
    /// stand-in driver for offline evaluation of perception).
    Follow,
    /// A controller's command (or the timeout policy's brake).
    Command(ControlCommand),
}

/// A collision that started in the last step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Collision {
    pub id_a: u32,
    pub id_b: u32,
    /// Speed of one relative to the other just before contact.
    pub relative_speed_mps: f64,
}

impl Collision {
    /// Whether vehicle `id` is one of the two.
    pub(crate) fn involves(&self, id: u32) -> bool {
        self.id_a == id || self.id_b == id
    }

    pub fn involves_ego(&self) -> bool {
        self.involves(EGO_ID)
    }

    /// The other vehicle than `id`.
    pub(crate) fn other_than(&self, id: u32) -> u32 {
        if self.id_a == id {
            self.id_b
        } else {
            self.id_a
        }
    }
}

/// Why a scenario ended.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct End {
    pub reason: String,
    pub success: bool,
}

/// What one step produced besides the new state.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct StepEvents {
    pub collisions: Vec<Collision>,
    pub ended: Option<End>,
}

struct Body {
    id: u32,
    class: ObjectClass,
    params: VehicleParams,
    color: [u8; 3],
    body: BodyId,
    driver: Option<TrafficDriver>,
    /// Throttle and brake as applied: the commanded ones through the actuator lag.
    applied: Actuation,
    /// The brake as commanded (the pedal): the brake lights follow it, not the lagging brake.
    pedal_brake: f64,
}

/// What the world keeps of one controlled vehicle besides its body (body `k` for ego `k`).
struct EgoSlot {
    /// Drives it before a controller speaks (`EgoInput::Cruise`, `Follow`).
    cruise: Cruise,
    /// The command taken this step, as vehicle/state reports it.
    applied: ControlCommand,
    accel_body: Vector2<f64>,
    start_s: f64,
    collisions: u64,
    /// Its own speed sensor's noise, drawn from a stream of its own: one ego's readings do
    /// not change with how many others there are.
    noise: SimRng,
}

/// The world and its clock.
pub struct World {
    scenario: Scenario,
    seed: u64,
    road: Road,
    physics: Physics,
    physics_hz: u32,
    step: u64,
    bodies: Vec<Body>,
    views: Vec<VehicleView>,
    egos: Vec<EgoSlot>,
    /// Collisions between two egos (each also counts in both egos' own).
    between_egos: u64,
    traffic_collisions: u64,
    end: Option<End>,
}

/// Vehicles being placed at a scenario's start (the ego first, id 0).
struct Placing<'a> {
    road: &'a Road,
    physics: Physics,
    bodies: Vec<Body>,
    /// (lane, s of the rear axle) of every vehicle placed: random traffic keeps its distance.
    starts: Vec<(u32, f64)>,
}

impl Placing<'_> {
    fn next_id(&self) -> u32 {
        self.bodies.len() as u32
    }

    /// A vehicle at road position `s` (rear axle) in `lane`, `offset_m` left of its centre,
    /// moving at `speed`.
    #[allow(clippy::too_many_arguments)]
    fn add(
        &mut self,
        class: ObjectClass,
        color: [u8; 3],
        lane: u32,
        offset_m: f64,
        s: f64,
        speed: f64,
        driver: Option<TrafficDriver>,
    ) {
        let id = self.next_id();
        let params = VehicleParams::of_class(class);
        let (_, heading) = self.road.center(s);
        let at = self.road.to_world(s, self.road.lane_center_d(lane) + offset_m);
        let body = self.physics.add_vehicle(id, &params, at, heading, speed);
        self.starts.push((lane, s));
        // Starting at speed: the throttle that holds it is already applied.
        let (throttle, brake) = actuate_acceleration(&params, speed, 0.0);
        let applied = Actuation { throttle, brake, steer: 0.0 };
        self.bodies.push(Body { id, class, params, color, body, driver, applied, pedal_brake: 0.0 });
    }

    /// The scenario's scripted traffic, placed from the first ego: start gaps and speeds vary
    /// a little with the seed.
    fn scripted_traffic(&mut self, scenario: &Scenario, rng: &mut SimRng) {
        let ego = &self.bodies[0].params;
        let ego_s = scenario.ego().s_m;
        let (ego_front, ego_rear) = (ego_s - ego.rear_overhang_m + ego.size_m[0], ego_s - ego.rear_overhang_m);
        let variation = &scenario.variation;
        for t in &scenario.traffic {
            let mut vrng = rng.fork(self.next_id() as u64);
            let params = VehicleParams::of_class(t.class.into());
            let gap = t.gap_m + vrng.range(-variation.gap_m, variation.gap_m);
            let speed = (t.speed_mps + vrng.range(-variation.speed_mps, variation.speed_mps)).max(0.0);
            let s = if t.gap_m >= 0.0 {
                ego_front + gap.max(0.5) + params.rear_overhang_m
            } else {
                ego_rear + gap.min(-0.5) - (params.size_m[0] - params.rear_overhang_m)
            };
            let color = t.color.unwrap_or(PALETTE[vrng.below(PALETTE.len() as u64) as usize]);
            let driver = TrafficDriver::new(t.lane, t.offset_m, speed, t.follow, t.actions.clone(), None);
            self.add(t.class.into(), color, t.lane, t.offset_m, s, speed, Some(driver));
        }
    }

    /// Generated traffic: random lanes, positions, speeds, classes; never too close to a
    /// vehicle already placed (up to 30 tries each).
    fn random_traffic(&mut self, r: &RandomTraffic, ego_s: f64, rng: &mut SimRng) {
        let lanes: Vec<u32> = if r.lanes.is_empty() { (0..self.road.lanes()).collect() } else { r.lanes.clone() };
        let mut grng = rng.fork(0xBEEF);
        for _ in 0..r.count {
            for _attempt in 0..30 {
                let lane = lanes[grng.below(lanes.len() as u64) as usize];
                let s = ego_s + grng.range(r.range_m[0], r.range_m[1]);
                if s < 10.0 || self.starts.iter().any(|&(l, s2)| l == lane && (s - s2).abs() < r.min_spacing_m) {
                    continue;
                }
                let id = self.next_id();
                let pick = grng.unit();
                let class = if pick < r.truck_share {
                    ClassSpec::Truck
                } else if pick < r.truck_share + r.van_share {
                    ClassSpec::Van
                } else {
                    ClassSpec::Car
                };
                let speed = grng.range(r.speed_mps[0], r.speed_mps[1]);
                let color = PALETTE[grng.below(PALETTE.len() as u64) as usize];
                let wander = r.lane_change_every_s.map(|every| Wander {
                    mean_interval_s: every,
                    lanes: lanes.clone(),
                    next_s: every * (0.5 + grng.unit()),
                    rng: grng.fork(id as u64),
                });
                let driver = TrafficDriver::new(lane, 0.0, speed, true, Vec::new(), wander);
                self.add(class.into(), color, lane, 0.0, s, speed, Some(driver));
                break;
            }
        }
    }
}

impl World {
    /// Builds the start of `scenario` with `seed` (the scenario's own unless overridden).
    pub fn new(scenario: Scenario, seed: u64, physics_hz: u32) -> World {
        let dt = 1.0 / physics_hz as f64;
        let road = Road::new(scenario.road.clone());
        let mut rng = SimRng::new(seed);
        let mut placing = Placing { road: &road, physics: Physics::new(dt), bodies: Vec::new(), starts: Vec::new() };
        for ego in scenario.egos() {
            let color = ego.color.unwrap_or([235, 235, 235]);
            placing.add(ego.class.into(), color, ego.lane, 0.0, ego.s_m, ego.speed_mps, None);
        }
        placing.scripted_traffic(&scenario, &mut rng);
        if let Some(r) = &scenario.random_traffic {
            placing.random_traffic(r, scenario.ego().s_m, &mut rng);
        }
        let Placing { physics, bodies, starts, .. } = placing;
        // The first ego's noise stream is the one a single-ego world always drew from.
        let mut noise = rng.fork(0x5EED);
        let mut egos = Vec::with_capacity(scenario.egos().len());
        for (k, spec) in scenario.egos().iter().enumerate() {
            egos.push(EgoSlot {
                cruise: Cruise::new(spec.speed_mps),
                applied: ControlCommand::NEUTRAL,
                accel_body: Vector2::zeros(),
                start_s: spec.s_m,
                collisions: 0,
                noise: if k == 0 { noise.clone() } else { noise.fork(k as u64) },
            });
        }
        let mut world = World {
            scenario,
            seed,
            road,
            physics,
            physics_hz,
            step: 0,
            bodies,
            views: Vec::new(),
            egos,
            between_egos: 0,
            traffic_collisions: 0,
            end: None,
        };
        let hints: Vec<f64> = starts.iter().map(|&(_, s)| s).collect();
        world.views = world.observe(&hints);
        world
    }

    fn observe(&self, s_hints: &[f64]) -> Vec<VehicleView> {
        self.bodies
            .iter()
            .zip(s_hints)
            .map(|(b, &hint)| {
                let state = self.physics.state(b.body);
                let rear_axle = self.physics.rear_axle(b.body);
                let (s, d) = self.road.project(rear_axle, hint);
                VehicleView {
                    id: b.id,
                    class: b.class,
                    params: b.params,
                    color: b.color,
                    rear_axle,
                    yaw_rad: state.yaw_rad,
                    velocity_mps: state.velocity_mps,
                    yaw_rate_radps: state.yaw_rate_radps,
                    s_m: s,
                    d_m: d,
                    lane: self.road.lane_at(d),
                    brake_lights: b.pedal_brake > BRAKE_LIGHT_PEDAL,
                }
            })
            .collect()
    }

    pub fn scenario(&self) -> &Scenario {
        &self.scenario
    }

    pub fn seed(&self) -> u64 {
        self.seed
    }

    pub fn road(&self) -> &Road {
        &self.road
    }

    pub fn physics_hz(&self) -> u32 {
        self.physics_hz
    }

    /// Steps taken so far.
    pub fn step_count(&self) -> u64 {
        self.step
    }

    /// Simulation time of the current state, exact in integer nanoseconds.
    pub fn time_ns(&self) -> u64 {
        (self.step as u128 * 1_000_000_000 / self.physics_hz as u128) as u64
    }

    /// Every vehicle after the last step; the ego first.
    pub fn vehicles(&self) -> &[VehicleView] {
        &self.views
    }

    /// The first ego.
    pub fn ego(&self) -> &VehicleView {
        &self.views[0]
    }

    /// How many controlled vehicles there are.
    pub fn ego_count(&self) -> usize {
        self.egos.len()
    }

    /// Ego `k` (the scenario's `egos[k]`).
    pub fn ego_at(&self, k: usize) -> &VehicleView {
        &self.views[k]
    }

    /// Which ego vehicle `id` is, if it is one.
    pub(crate) fn ego_index(&self, id: u32) -> Option<usize> {
        (id < self.egos.len() as u32).then_some(id as usize)
    }

    /// The first ego's collisions.
    pub fn ego_collisions(&self) -> u64 {
        self.egos[0].collisions
    }

    /// Ego `k`'s collisions (with traffic or another ego).
    pub fn collisions_of(&self, k: usize) -> u64 {
        self.egos[k].collisions
    }

    /// Collisions between two egos.
    pub fn collisions_between_egos(&self) -> u64 {
        self.between_egos
    }

    /// The first ego's throttle and brake as they act on the wheels now: the commanded ones
    /// through the actuator lag (vehicle/state's `applied` is the command taken).
    pub fn ego_actuation(&self) -> (f64, f64) {
        let a = self.bodies[0].applied;
        (a.throttle, a.brake)
    }

    pub fn traffic_collisions(&self) -> u64 {
        self.traffic_collisions
    }

    pub fn ended(&self) -> Option<&End> {
        self.end.as_ref()
    }

    /// The nearest vehicle ahead of `i` whose body overlaps its path.
    fn lead_of(&self, i: usize) -> Option<Lead> {
        let me = &self.views[i];
        let lateral_room = |o: &VehicleView| (me.params.size_m[1] + o.params.size_m[1]) / 2.0 + 0.2;
        self.views
            .iter()
            .enumerate()
            .filter(|(j, o)| *j != i && o.s_m > me.s_m && (o.d_m - me.d_m).abs() < lateral_room(o))
            .min_by(|a, b| a.1.s_m.total_cmp(&b.1.s_m))
            .map(|(_, o)| Lead { gap_m: o.s_rear_m() - me.s_front_m(), speed_mps: o.forward_speed_mps() })
    }

    /// Advances one physics step with the first ego driven by `input` (any further egos cruise).
    pub fn step(&mut self, input: EgoInput) -> StepEvents {
        let mut inputs = vec![EgoInput::Cruise; self.egos.len()];
        inputs[0] = input;
        self.step_all(&inputs)
    }

    /// Advances one physics step with ego `k` driven by `inputs[k]` (missing ones cruise).
    pub fn step_all(&mut self, inputs: &[EgoInput]) -> StepEvents {
        let dt = 1.0 / self.physics_hz as f64;
        let t_s = self.step as f64 * dt;
        // Each driver decides from the same snapshot, so the order of vehicles does not matter.
        let neighbours = self.neighbours();
        let mut actuations = Vec::with_capacity(self.bodies.len());
        for k in 0..self.egos.len() {
            let input = inputs.get(k).copied().unwrap_or(EgoInput::Cruise);
            actuations.push(self.ego_input(k, input, dt));
        }
        self.traffic_actuations(&neighbours, t_s, dt, &mut actuations);
        for (b, act) in self.bodies.iter_mut().zip(&actuations) {
            let lag = b.params.actuator_lag_s;
            b.applied.throttle = lag_toward(b.applied.throttle, act.throttle.clamp(0.0, 1.0), lag, dt);
            b.applied.brake = lag_toward(b.applied.brake, act.brake.clamp(0.0, 1.0), lag, dt);
            b.pedal_brake = act.brake.clamp(0.0, 1.0);
            b.applied.steer = act.steer;
            let state = self.physics.state(b.body);
            let wrench = forces(&b.params, &state, &b.applied, dt);
            self.physics.apply(b.body, &wrench, dt);
        }
        let started = self.physics.step();
        self.step += 1;

        let before = std::mem::take(&mut self.views);
        let hints: Vec<f64> = before.iter().map(|v| v.s_m).collect();
        self.views = self.observe(&hints);
        for (k, ego) in self.egos.iter_mut().enumerate() {
            let now = self.views[k];
            let accel_world = (now.velocity_mps - before[k].velocity_mps) / dt;
            ego.accel_body = Rotation2::new(-now.yaw_rad) * accel_world;
        }

        let mut events = StepEvents { collisions: self.collisions(started, &before), ..StepEvents::default() };
        if self.end.is_none() {
            self.end = self.check_end(&events);
            events.ended = self.end.clone();
        }
        events
    }

    /// Every vehicle as the drivers see it before this step.
    fn neighbours(&self) -> Vec<Neighbour> {
        self.views
            .iter()
            .zip(&self.bodies)
            .map(|(v, b)| Neighbour {
                id: v.id,
                rear_m: v.s_rear_m(),
                front_m: v.s_front_m(),
                lane: v.lane,
                target_lane: b.driver.as_ref().map_or(v.lane, |d| d.lane() as i32),
                speed_mps: v.forward_speed_mps(),
            })
            .collect()
    }

    /// Ego `k`'s pedals and steering for this step: its own cruise controller (`Cruise`,
    /// `Follow`) or the command received, plus lane keeping when the scenario asks for it.
    fn ego_input(&mut self, k: usize, input: EgoInput, dt: f64) -> Actuation {
        let ego = self.views[k];
        let ego_params = self.bodies[k].params;
        let lane_keep = |world: &World| -> f64 {
            let spec = &world.scenario.egos()[k];
            if !spec.lane_keeping {
                return 0.0;
            }
            let lane = if ego.lane >= 0 { ego.lane as u32 } else { spec.lane };
            pursue(&ego_params, &world.road, &ego.observation(), world.road.lane_center_d(lane))
        };
        match input {
            EgoInput::Cruise | EgoInput::Follow => {
                let lead = if input == EgoInput::Follow { self.lead_of(k) } else { None };
                let (throttle, brake) =
                    self.egos[k].cruise.longitudinal(&ego_params, ego.forward_speed_mps(), lead, dt);
                self.egos[k].applied =
                    ControlCommand { throttle: throttle as f32, brake: brake as f32, ..ControlCommand::NEUTRAL };
                Actuation { throttle, brake, steer: lane_keep(self) }
            }
            EgoInput::Command(cmd) => {
                self.egos[k].applied = cmd;
                Actuation {
                    throttle: cmd.throttle as f64,
                    brake: cmd.brake as f64,
                    steer: (cmd.steer as f64 + lane_keep(self)).clamp(-1.0, 1.0),
                }
            }
        }
    }

    /// Each traffic vehicle's driver decides (a vehicle without one coasts), appended to
    /// `actuations` in body order. Its triggers go by the gap to the first ego.
    fn traffic_actuations(&mut self, neighbours: &[Neighbour], t_s: f64, dt: f64, actuations: &mut Vec<Actuation>) {
        let ego = self.views[0];
        for i in self.egos.len()..self.bodies.len() {
            let lead = self.lead_of(i);
            let view = self.views[i];
            let gap_to_ego = bumper_gap_m(&ego, &view);
            let params = self.bodies[i].params;
            let Some(driver) = self.bodies[i].driver.as_mut() else {
                actuations.push(Actuation::default());
                continue;
            };
            actuations.push(driver.drive(
                &params,
                &self.road,
                &view.observation(),
                lead,
                gap_to_ego,
                neighbours,
                t_s,
                dt,
            ));
        }
    }

    /// The contacts that started this step, with their relative speed before it, counted.
    fn collisions(&mut self, started: Vec<(u32, u32)>, before: &[VehicleView]) -> Vec<Collision> {
        let mut out = Vec::new();
        for (a, b) in started {
            let va = before.iter().find(|v| v.id == a).map(|v| v.velocity_mps).unwrap_or_default();
            let vb = before.iter().find(|v| v.id == b).map(|v| v.velocity_mps).unwrap_or_default();
            let collision = Collision { id_a: a, id_b: b, relative_speed_mps: (va - vb).norm() };
            let (ego_a, ego_b) = (self.ego_index(a), self.ego_index(b));
            for k in [ego_a, ego_b].into_iter().flatten() {
                self.egos[k].collisions += 1;
            }
            match (ego_a, ego_b) {
                (None, None) => self.traffic_collisions += 1,
                (Some(_), Some(_)) => self.between_egos += 1,
                _ => {}
            }
            out.push(collision);
        }
        out
    }

    fn check_end(&self, events: &StepEvents) -> Option<End> {
        let clean = self.egos.iter().all(|e| e.collisions == 0);
        if self.scenario.end.on_collision {
            for c in &events.collisions {
                let Some(k) = [c.id_a, c.id_b].into_iter().find_map(|id| self.ego_index(id)) else { continue };
                let who = self.ego_name(k);
                let other = c.other_than(k as u32);
                return Some(End {
                    reason: format!("{who} collided with vehicle {other} at {:.1} m/s", c.relative_speed_mps),
                    success: false,
                });
            }
        }
        if let Some(d) = self.scenario.end.ego_distance_m {
            if self.ego().s_m - self.egos[0].start_s >= d {
                return Some(End { reason: format!("ego travelled {d} m"), success: clean });
            }
        }
        if self.time_ns() >= (self.scenario.duration_s * 1e9) as u64 {
            return Some(End { reason: format!("duration of {} s reached", self.scenario.duration_s), success: clean });
        }
        None
    }

    /// How messages name ego `k`: "ego" when it is the only one, else its namespace.
    pub(crate) fn ego_name(&self, k: usize) -> String {
        match (self.egos.len(), &self.scenario.egos()[k].namespace) {
            (1, _) | (_, None) => "ego".to_string(),
            (_, Some(ns)) => format!("ego {ns}"),
        }
    }

    /// The first ego's speed as vehicle/speed reports it, with the scenario's sensor noise.
    pub fn measured_speed_mps(&mut self) -> f64 {
        self.measured_speed_of(0)
    }

    /// Ego `k`'s speed as its vehicle/speed reports it, with the scenario's sensor noise.
    pub(crate) fn measured_speed_of(&mut self, k: usize) -> f64 {
        let sd = self.scenario.noise.speed_mps;
        self.views[k].forward_speed_mps() + self.egos[k].noise.normal(sd)
    }

    /// The first ego's full state (vehicle/state).
    pub fn ego_state(&self) -> VehicleState {
        self.ego_state_of(0)
    }

    /// Ego `k`'s full state (its vehicle/state).
    pub fn ego_state_of(&self, k: usize) -> VehicleState {
        let e = &self.views[k];
        let slot = &self.egos[k];
        VehicleState {
            step: self.step,
            position_in_world_m: [e.rear_axle.x, e.rear_axle.y, 0.0],
            yaw_in_world_rad: e.yaw_rad,
            pitch_rad: 0.0,
            roll_rad: 0.0,
            velocity_in_world_mps: [e.velocity_mps.x, e.velocity_mps.y, 0.0],
            acceleration_in_body_mps2: [slot.accel_body.x, slot.accel_body.y, 0.0],
            yaw_rate_radps: e.yaw_rate_radps,
            speed_mps: e.forward_speed_mps(),
            lane: e.lane,
            applied: slot.applied,
            // Wall-clock timing is the node's business (sim::node fills it in).
            control_timing: None,
        }
    }
}
