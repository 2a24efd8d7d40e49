//! slipstream-acc on the bus: vehicle/speed + vehicle/state + perception (perception/objects,
//! or objects for ground truth) + acc/command -> vehicle/control (one per speed message, naming
//! the step it answers) and acc/status.
//!
//! Input health, checked at every speed message and by a wall-clock watchdog:
//! - perception older than `stale.perception_max_age_ms` of simulated time (header stamps),
//!   or the detector's liveliness token gone: StalePerception / PerceptionLost;
//! - no vehicle/speed for `stale.speed_max_age_ms` of wall time: StaleSpeed, and the watchdog
//!   keeps publishing braking commands (answering no step) until speed returns; not in
//!   lockstep, where the simulator waits for this node and wall time says nothing of staleness.
//!
//! Any of them puts the controller in Stale mode (throttle off, smooth braking); it recovers
//! by itself when fresh data return.

use std::future::Future;
use std::time::{Duration, Instant};

use serde::Serialize;

use super::controller::{Controller, Output};
use super::ego::{EgoNow, EgoSpeedFilter, Pose};
use super::objects::PerceptionFrame;
use super::settings::{AccSettings, FromScenario, PerceptionSource};
use slipstream_contract::bus::{Arrivals, Bus, BusError, Following, NodeWatch, Received, StatsSnapshot, Subscriber};
use slipstream_contract::config::ConfigError;
use slipstream_contract::msg::{
    AccCommand, AccMode, AccStatus, AccWarning, CameraInfo, ControlCommand, Detections, EgoInfo, GroundTruthObjects,
    Message, RoadSpec, Speed, VehicleState,
};
use slipstream_contract::topics;

/// What a run did.
#[derive(Debug, Clone, Default, Serialize, serde::Deserialize)]
#[serde(default)]
pub struct AccStats {
    /// vehicle/control messages answering a speed message.
    pub commands: u64,
    /// Braking commands the watchdog sent while vehicle/speed was stale.
    pub watchdog_commands: u64,
    pub status: u64,
    pub perception_frames: u64,
    /// Times the ACC entered Stale or Emergency mode.
    pub stale_episodes: u64,
    pub emergencies: u64,
    /// Lockstep steps whose perception did not come within lockstep_wait_ms (after one, the
    /// frames are not waited for until perception comes again).
    pub lockstep_waits_timed_out: u64,
    /// Outside lockstep: answers whose frame's perception did not come within
    /// perception_wait_ms (answered with the perception there was).
    pub perception_waits_timed_out: u64,
    /// Answers given without the vehicle/state of their step (it came too late).
    pub state_waits_timed_out: u64,
    /// Speed, state, perception and command messages from another publisher than the one
    /// followed (see `Following`; commands keep their first operator): not used.
    pub foreign_inputs: u64,
    /// Wall time spent computing answers (inputs taken, controller stepped), seconds.
    pub busy_s: f64,
    /// Wall time answers waited for their step's state and perception, seconds.
    pub waiting_s: f64,
    /// The inputs' statistics at the end: received, lost on the way (sequence gaps), dropped
    /// or delayed by injected faults (`--faults`).
    pub inputs: Vec<StatsSnapshot>,
}

/// The perception input, by source.
enum PerceptionSub {
    Camera(Subscriber<Detections>),
    GroundTruth(Subscriber<GroundTruthObjects>),
}

impl PerceptionSub {
    fn arrivals(&self) -> &Arrivals {
        match self {
            PerceptionSub::Camera(s) => s.arrivals(),
            PerceptionSub::GroundTruth(s) => s.arrivals(),
        }
    }

    fn stats(&self) -> StatsSnapshot {
        match self {
            PerceptionSub::Camera(s) => s.stats().snapshot(),
            PerceptionSub::GroundTruth(s) => s.stats().snapshot(),
        }
    }

    /// The next waiting perception message, converted, with its header.stamp_pub_ns and its
    /// publisher.
    fn frame(&self) -> Option<(PerceptionFrame, u64, Option<String>)> {
        let convert_d = |r: Received<Detections>| {
            let f = PerceptionFrame::from_detections(r.header.stamp_sim_ns as f64 / 1e9, &r.msg);
            (f, r.header.stamp_pub_ns, r.source)
        };
        let convert_g = |r: Received<GroundTruthObjects>| {
            let f = PerceptionFrame::from_ground_truth(r.header.stamp_sim_ns as f64 / 1e9, &r.msg);
            (f, r.header.stamp_pub_ns, r.source)
        };
        match self {
            PerceptionSub::Camera(s) => s.try_recv().map(convert_d),
            PerceptionSub::GroundTruth(s) => s.try_recv().map(convert_g),
        }
    }
}

/// Logs at most once per `every`.
struct Every {
    every: Duration,
    last: Option<Instant>,
    suppressed: u64,
}

impl Every {
    fn new(every: Duration) -> Self {
        Every { every, last: None, suppressed: 0 }
    }

    /// Some(count suppressed since the last time) when it is time to log.
    fn ready(&mut self) -> Option<u64> {
        let now = Instant::now();
        if self.last.is_some_and(|t| now.duration_since(t) < self.every) {
            self.suppressed += 1;
            return None;
        }
        self.last = Some(now);
        Some(std::mem::take(&mut self.suppressed))
    }
}

/// The node between messages: the controller, what it knows of the simulator's clock, and
/// its counters. Time is passed in (`now`), so the watchdog is tested on an injected clock.
struct State {
    ctl: Controller,
    ego: EgoNow,
    /// vehicle/speed smoothed with the measured acceleration: EgoNow's speed.
    ego_speed: EgoSpeedFilter,
    /// The newest vehicle/state: its stamp and step.
    state: Option<(u64, u64)>,
    /// Physics rate learned from vehicle/state (steps per simulated second).
    physics_hz: Option<f64>,
    perception_stamp_s: Option<f64>,
    /// header.stamp_pub_ns of the newest perception message taken (traced in vehicle/control).
    perception_pub_ns: Option<u64>,
    camera_rate_hz: Option<f64>,
    latched_waited: bool,
    /// sim/ego came (the scenario's driver settings taken, where no flag gave them).
    ego_known: bool,
    /// Lockstep: a wait for a frame's perception ran out and none has come since. The next
    /// frames are not waited for until perception comes again: a detector that publishes
    /// nothing (no camera info, a stuck process) must not cost every frame step
    /// lockstep_wait_ms and turn the run into a crawl.
    perception_overdue: bool,
    last_speed_at: Option<Instant>,
    speed_max_age: Duration,
    mode: Option<AccMode>,
    status_tick: Option<i64>,
    stats: AccStats,
    wait_log: Every,
    speed_from: Following,
    state_from: Following,
    perception_from: Following,
    command_from: Following,
}

/// A command to publish, with the status when one is due.
struct Answer {
    stamp_ns: u64,
    command: ControlCommand,
    status: Option<AccStatus>,
}

/// How often the watchdog looks at the age of vehicle/speed.
const WATCHDOG_PERIOD: Duration = Duration::from_millis(50);
/// How long an answer waits for the vehicle/state of its step (published right after speed),
/// outside lockstep.
const STATE_WAIT: Duration = Duration::from_millis(20);
/// Lockstep log lines about missing perception: at most one per this.
const LOCKSTEP_LOG_EVERY: Duration = Duration::from_secs(5);

/// The node's subscriptions.
struct Inputs {
    speed: Subscriber<Speed>,
    state: Subscriber<VehicleState>,
    command: Subscriber<AccCommand>,
    info: Subscriber<CameraInfo>,
    /// The road's map (latched): the lane ahead.
    road: Subscriber<RoadSpec>,
    /// The ego's vehicle and the scenario's driver settings (latched).
    ego: Subscriber<EgoInfo>,
    perception: PerceptionSub,
    /// The detector's liveliness (camera perception only).
    detector: Option<NodeWatch>,
}

impl Inputs {
    async fn open(bus: &Bus, settings: &AccSettings) -> Result<Inputs, BusError> {
        let perception = match settings.perception {
            PerceptionSource::Camera => PerceptionSub::Camera(bus.subscriber(topics::PERCEPTION_OBJECTS).await?),
            PerceptionSource::GroundTruth => PerceptionSub::GroundTruth(bus.subscriber(topics::OBJECTS).await?),
        };
        let detector = match settings.perception {
            PerceptionSource::Camera => Some(bus.watch_node(&settings.perception_node).await?),
            PerceptionSource::GroundTruth => None,
        };
        Ok(Inputs {
            speed: bus.subscriber(topics::VEHICLE_SPEED).await?,
            state: bus.subscriber(topics::VEHICLE_STATE).await?,
            command: bus.subscriber(topics::ACC_COMMAND).await?,
            info: bus.subscriber(topics::CAMERA_FRONT_INFO).await?,
            road: bus.subscriber(topics::SIM_ROAD).await?,
            ego: bus.subscriber(topics::SIM_EGO).await?,
            perception,
            detector,
        })
    }

    fn detector_alive(&self) -> bool {
        self.detector.as_ref().is_none_or(|d| d.is_alive())
    }
}

/// Runs until `shutdown` completes.
pub async fn run(bus: &Bus, settings: AccSettings, shutdown: impl Future<Output = ()>) -> Result<AccStats, BusError> {
    if let Some(profile) = bus.faults() {
        if settings.lockstep && profile.at(topics::VEHICLE_SPEED.topic, bus.node()).is_some() {
            return Err(ConfigError::new(
                &profile.name,
                "topics.vehicle/speed",
                "faults on vehicle/speed at a lockstep ACC: each lost speed message would leave a simulator step unanswered",
                "inject the loop's faults on perception/objects, objects, vehicle/state and vehicle/control in lockstep, or run the clock in realtime or fast mode",
            )
            .into());
        }
    }
    let inputs = Inputs::open(bus, &settings).await?;
    if settings.lockstep {
        bus.keep_every_message();
    }
    let control_pub = bus.publisher(topics::VEHICLE_CONTROL).await?;
    let status_pub = bus.publisher(topics::ACC_STATUS).await?;
    // Seen once it listens: the simulator in lockstep steps on when it sees us, and the
    // perception of a step published before our subscriber existed would never come.
    bus.announce().await?;
    tracing::info!(
        perception = ?settings.perception,
        lockstep = settings.lockstep,
        set_speed_mps = settings.set_speed_mps,
        time_gap_s = settings.time_gap_s,
        "acc up; waiting for vehicle/speed"
    );
    let mut st = State::new(settings.clone());
    let mut watchdog = tokio::time::interval(WATCHDOG_PERIOD);
    watchdog.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Skip);
    tokio::pin!(shutdown);
    loop {
        let answer = tokio::select! {
            _ = &mut shutdown => break,
            speed = inputs.speed.recv() => {
                if !st.speed_from.accept(speed.source.as_deref(), Instant::now()) {
                    continue;
                }
                answer_speed(&mut st, &inputs, &settings, speed).await
            }
            // In lockstep the simulator does not step on without this node's answer: a speed
            // message late by the wall clock is the simulator's pace on a loaded machine, not
            // a stale input, and a watchdog step there would make the run depend on that pace.
            _ = watchdog.tick(), if !settings.lockstep => match st.watchdog(Instant::now(), inputs.detector_alive()) {
                Some(a) => a,
                None => continue,
            },
        };
        control_pub.put(answer.stamp_ns, &answer.command)?;
        if let Some(status) = &answer.status {
            status_pub.put(answer.stamp_ns, status)?;
        }
    }
    st.stats.foreign_inputs = st.speed_from.rejected()
        + st.state_from.rejected()
        + st.perception_from.rejected()
        + st.command_from.rejected();
    st.stats.inputs = vec![
        inputs.speed.stats().snapshot(),
        inputs.state.stats().snapshot(),
        inputs.perception.stats(),
        inputs.command.stats().snapshot(),
    ];
    Ok(st.stats)
}

/// Everything one vehicle/speed message leads to: the state of its step, commands, camera
/// info, perception (awaited in lockstep), then the controller's answer.
async fn answer_speed(st: &mut State, inputs: &Inputs, settings: &AccSettings, speed: Received<Speed>) -> Answer {
    st.last_speed_at = Some(Instant::now());
    let t_ns = speed.header.stamp_sim_ns;
    let t_s = t_ns as f64 / 1e9;
    // In lockstep the answer must not depend on how fast the state travelled: wait for it as
    // long as for perception. Otherwise never hold the answer long for it.
    let state_wait = if settings.lockstep { Duration::from_millis(settings.lockstep_wait_ms) } else { STATE_WAIT };
    let waiting = Instant::now();
    let state = await_state(st, &inputs.state, t_ns, state_wait).await;
    let mut waited = waiting.elapsed();
    let answers_step = answers_step(st, t_ns);
    let accel_mps2 = state.as_ref().map_or(st.ego.accel_mps2, |s| s.acceleration_in_body_mps2[0]);
    // Measured once a vehicle/state has come (held from the last one when this step's is late).
    let measured_accel = st.state.is_some().then_some(accel_mps2);
    st.ego = EgoNow {
        t_s,
        speed_mps: st.ego_speed.update(t_s, speed.msg.speed_mps, measured_accel),
        accel_mps2,
        yaw_rate_radps: state.as_ref().map_or(st.ego.yaw_rate_radps, |s| s.yaw_rate_radps),
        pose: state.as_ref().map(Pose::of).or(st.ego.pose),
    };
    while let Some(c) = inputs.command.try_recv() {
        if !st.command_from.accept(c.source.as_deref(), Instant::now()) {
            continue;
        }
        if let Some(note) = st.ctl.command(&c.msg) {
            tracing::warn!("acc/command: {note}");
        }
    }
    take_latched(st, inputs, settings).await;
    while let Some((frame, pub_ns, source)) = inputs.perception.frame() {
        if st.perception_from.accept(source.as_deref(), Instant::now()) {
            take_perception(st, &frame, pub_ns);
        }
    }
    // Something arrived already, even if injected faults hold it back.
    let seen_any = inputs.perception.arrivals().since(0);
    // The answer waits for the perception of the frame taken at this step: in lockstep (the
    // run must not depend on timing) unless the last wait ran out, briefly otherwise (the loop reacts to the frame
    // now rather than at the next speed message), and not at all in realtime once the
    // detector is known gone (nothing will come; each frame step would lose the wait).
    let wait_ms = match settings.lockstep {
        true if st.perception_overdue => 0,
        true => settings.lockstep_wait_ms,
        false if !inputs.detector_alive() => 0,
        false => settings.perception_wait_ms,
    };
    if wait_ms > 0 && st.frame_expected_at(t_s, seen_any) && !st.has_perception_at(t_s) {
        let waiting = Instant::now();
        await_perception(st, &inputs.perception, wait_ms, t_ns, settings.lockstep).await;
        waited += waiting.elapsed();
    }
    let answer = st.answer(t_ns, answers_step, inputs.detector_alive());
    // Up to date from here: time spent waiting above (lockstep) does not age the speed.
    let now = Instant::now();
    let spent = now.duration_since(st.last_speed_at.unwrap_or(now));
    st.stats.waiting_s += waited.as_secs_f64();
    st.stats.busy_s += spent.saturating_sub(waited).as_secs_f64();
    st.last_speed_at = Some(now);
    answer
}

/// The vehicle/state of the step stamped `t_ns` (published right after its speed), waiting
/// at most `wait` for it to arrive; the newest state taken, if any. One that arrived but was
/// dropped or held back by injected faults is not waited for.
async fn await_state(
    st: &mut State,
    sub: &Subscriber<VehicleState>,
    t_ns: u64,
    wait: Duration,
) -> Option<VehicleState> {
    let deadline = Instant::now() + wait;
    let mut state = None;
    loop {
        // Arrival first: a message seen arrived was handed on before, so the drain gets it.
        let arrived = sub.arrivals().since(t_ns);
        if let Some(s) = drain_states(sub, st) {
            state = Some(s);
        }
        if arrived || st.state.is_some_and(|(stamp, _)| stamp >= t_ns) {
            return state;
        }
        let left = deadline.saturating_duration_since(Instant::now());
        if left.is_zero() {
            st.stats.state_waits_timed_out += 1;
            return state;
        }
        sub.arrivals().wait(left, || sub.arrivals().since(t_ns)).await;
    }
}

/// The camera's rate (camera/front/info) and the road's map (sim/road), both latched. In
/// lockstep the answers follow from them (which steps bring a frame, where the lane goes): wait
/// for the missing ones once, together, or one taken a step late makes the run differ.
/// The scenario's driver settings from sim/ego, where no flag gave them
/// ([`AccSettings::from_scenario`]).
fn take_ego(st: &mut State, ego: &EgoInfo, settings: &AccSettings) {
    st.ego_known = true;
    if let Some(cmd) = settings.from_scenario.command(ego) {
        tracing::info!(set_speed_mps = ?cmd.set_speed_mps, time_gap_s = ?cmd.time_gap_s, "sim/ego: the scenario's driver settings");
        if let Some(note) = st.ctl.command(&cmd) {
            tracing::warn!("sim/ego: {note}");
        }
    }
}

async fn take_latched(st: &mut State, inputs: &Inputs, settings: &AccSettings) {
    while let Some(info) = inputs.info.try_recv() {
        st.camera_rate_hz = Some(info.msg.rate_hz);
    }
    while let Some(road) = inputs.road.try_recv() {
        st.ctl.set_road(&road.msg);
    }
    while let Some(ego) = inputs.ego.try_recv() {
        take_ego(st, &ego.msg, settings);
    }
    if !settings.lockstep || st.latched_waited {
        return;
    }
    st.latched_waited = true;
    let wait = Duration::from_millis(settings.lockstep_wait_ms);
    let wants_ego = !st.ego_known && settings.from_scenario != FromScenario { set_speed: false, time_gap: false };
    let (info, road, ego) = tokio::join!(
        awaited(st.camera_rate_hz.is_none(), &inputs.info, wait),
        awaited(!st.ctl.has_road(), &inputs.road, wait),
        awaited(wants_ego, &inputs.ego, wait)
    );
    if let Awaited::Came(ego) = ego {
        take_ego(st, &ego.msg, settings);
    }
    match info {
        Awaited::Came(info) => st.camera_rate_hz = Some(info.msg.rate_hz),
        Awaited::Missing => tracing::warn!(
            waited_ms = settings.lockstep_wait_ms,
            "lockstep: no camera/front/info; perception is awaited only for the first frame"
        ),
        Awaited::Known => {}
    }
    match road {
        Awaited::Came(road) => st.ctl.set_road(&road.msg),
        Awaited::Missing => tracing::info!(
            waited_ms = settings.lockstep_wait_ms,
            "lockstep: no sim/road (optional); the lane ahead is predicted from the yaw rate"
        ),
        Awaited::Known => {}
    }
}

/// A latched input in lockstep: known already, come within the wait, or missing.
enum Awaited<M> {
    Known,
    Came(Received<M>),
    Missing,
}

async fn awaited<M: Message>(missing: bool, sub: &Subscriber<M>, wait: Duration) -> Awaited<M> {
    if !missing {
        return Awaited::Known;
    }
    sub.recv_timeout(wait).await.map_or(Awaited::Missing, Awaited::Came)
}

/// Waits up to `wait_ms` for the perception of the frame at `t_ns` to arrive (taken when
/// delivered; not waited for when injected faults dropped or held it). A wait that runs out
/// is counted: in lockstep it is a warning (is the detector running?), outside it a late
/// frame (the answer uses the perception there is).
async fn await_perception(st: &mut State, perception: &PerceptionSub, wait_ms: u64, t_ns: u64, lockstep: bool) {
    let t_s = t_ns as f64 / 1e9;
    let deadline = Instant::now() + Duration::from_millis(wait_ms);
    loop {
        let arrived = perception.arrivals().since(t_ns);
        while let Some((frame, pub_ns, source)) = perception.frame() {
            if st.perception_from.accept(source.as_deref(), Instant::now()) {
                take_perception(st, &frame, pub_ns);
            }
        }
        if arrived || st.has_perception_at(t_s) {
            return;
        }
        let left = deadline.saturating_duration_since(Instant::now());
        if left.is_zero() {
            break;
        }
        perception.arrivals().wait(left, || perception.arrivals().since(t_ns)).await;
    }
    st.perception_overdue = lockstep;
    let counter = match lockstep {
        true => &mut st.stats.lockstep_waits_timed_out,
        false => &mut st.stats.perception_waits_timed_out,
    };
    *counter += 1;
    let Some(more) = st.wait_log.ready() else { return };
    if lockstep {
        tracing::warn!(
            t_s,
            waited_ms = wait_ms,
            suppressed = more,
            "lockstep: no perception for the frame at this step; answering with what there is, and not waiting again until perception comes (is the detector running? has it camera info?)"
        );
    } else {
        tracing::info!(
            t_s,
            waited_ms = wait_ms,
            suppressed = more,
            "the perception of this step's frame came later than perception_wait_ms; answered with the one before"
        );
    }
}

impl State {
    fn new(settings: AccSettings) -> State {
        State {
            speed_max_age: Duration::from_millis(settings.stale.speed_max_age_ms),
            ctl: Controller::new(settings),
            ego: EgoNow::default(),
            ego_speed: EgoSpeedFilter::default(),
            state: None,
            physics_hz: None,
            perception_stamp_s: None,
            perception_pub_ns: None,
            camera_rate_hz: None,
            latched_waited: false,
            ego_known: false,
            perception_overdue: false,
            last_speed_at: None,
            mode: None,
            status_tick: None,
            stats: AccStats::default(),
            wait_log: Every::new(LOCKSTEP_LOG_EVERY),
            speed_from: Following::new("vehicle/speed"),
            state_from: Following::new("vehicle/state"),
            perception_from: Following::new("perception"),
            command_from: Following::first_only("acc/command"),
        }
    }

    fn ego_stamp_ns(&self) -> u64 {
        (self.ego.t_s * 1e9) as u64
    }

    fn has_perception_at(&self, t_s: f64) -> bool {
        self.perception_stamp_s.is_some_and(|p| p >= t_s - 1e-9)
    }

    /// The controller's answer to the speed message stamped `t_ns`.
    fn answer(&mut self, t_ns: u64, answers_step: Option<u64>, detector_alive: bool) -> Answer {
        let t_s = t_ns as f64 / 1e9;
        let mut warnings = Vec::new();
        let max_age = self.ctl.settings().stale.perception_max_age_ms as f64 / 1e3;
        if self.perception_stamp_s.is_none_or(|p| t_s - p > max_age) {
            warnings.push(AccWarning::StalePerception);
        }
        if !detector_alive {
            warnings.push(AccWarning::PerceptionLost);
        }
        let out = self.ctl.step(&self.ego, &warnings);
        self.note_mode(out.status.mode, &out.status.warnings);
        self.stats.commands += 1;
        let tick = (t_s * self.ctl.settings().status_hz + 1e-9).floor() as i64;
        let status = (self.status_tick != Some(tick)).then(|| {
            self.status_tick = Some(tick);
            self.stats.status += 1;
            out.status.clone()
        });
        Answer { stamp_ns: t_ns, command: self.command(&out, answers_step), status }
    }

    /// The watchdog at wall-clock time `now`: while vehicle/speed is older than
    /// `stale.speed_max_age_ms`, a braking command answering no step (and its status).
    fn watchdog(&mut self, now: Instant, detector_alive: bool) -> Option<Answer> {
        let since = now.saturating_duration_since(self.last_speed_at?);
        if since <= self.speed_max_age {
            return None;
        }
        // Simulated time moves on with the wall clock as far as the ACC can tell.
        let ego = EgoNow { t_s: self.ego.t_s + since.as_secs_f64(), ..self.ego };
        let mut warnings = vec![AccWarning::StaleSpeed];
        if !detector_alive {
            warnings.push(AccWarning::PerceptionLost);
        }
        let out = self.ctl.step(&ego, &warnings);
        self.note_mode(out.status.mode, &out.status.warnings);
        self.stats.watchdog_commands += 1;
        self.stats.status += 1;
        let command = self.command(&out, None);
        Some(Answer { stamp_ns: self.ego_stamp_ns(), command, status: Some(out.status) })
    }

    fn command(&self, out: &Output, answers_step: Option<u64>) -> ControlCommand {
        ControlCommand {
            throttle: out.throttle,
            brake: out.brake,
            steer: 0.0,
            answers_step,
            perception_stamp_pub_ns: self.perception_pub_ns,
        }
    }

    /// Whether a camera frame (and so a perception message) is due at simulated time `t_s`:
    /// the clock contract's rule (`msg::due`) with the camera rate from camera/front/info
    /// and the physics rate learned from vehicle/state.
    fn frame_expected_at(&self, t_s: f64, seen_any: bool) -> bool {
        match (self.camera_rate_hz, self.physics_hz) {
            (Some(rate), Some(hz)) => {
                let hz = hz.round().max(1.0);
                slipstream_contract::msg::due((t_s * hz).round() as u64, rate, hz as u32)
            }
            // Before the rates are known: the first frame comes with step 0.
            _ => self.perception_stamp_s.is_none() && !seen_any,
        }
    }

    fn note_mode(&mut self, mode: AccMode, warnings: &[AccWarning]) {
        if self.mode == Some(mode) {
            return;
        }
        match mode {
            AccMode::Stale => {
                self.stats.stale_episodes += 1;
                tracing::warn!(?warnings, "inputs stale: easing to the stale deceleration within the jerk limit");
            }
            AccMode::Emergency => self.stats.emergencies += 1,
            _ => {
                if self.mode == Some(AccMode::Stale) {
                    tracing::info!(?mode, "fresh inputs again: control resumed");
                } else {
                    tracing::debug!(?mode, "mode");
                }
            }
        }
        self.mode = Some(mode);
    }
}

fn take_state(st: &mut State, r: &Received<VehicleState>) {
    let stamp = r.header.stamp_sim_ns;
    if r.msg.step > 0 && stamp > 0 {
        st.physics_hz = Some(r.msg.step as f64 * 1e9 / stamp as f64);
    }
    st.state = Some((stamp, r.msg.step));
}

fn drain_states(sub: &Subscriber<VehicleState>, st: &mut State) -> Option<VehicleState> {
    let mut newest = None;
    while let Some(r) = sub.try_recv() {
        if st.state_from.accept(r.source.as_deref(), Instant::now()) {
            take_state(st, &r);
            newest = Some(r.msg);
        }
    }
    newest
}

/// The simulation step a speed message stamped `t_ns` belongs to.
fn answers_step(st: &State, t_ns: u64) -> Option<u64> {
    let (stamp, step) = st.state?;
    if stamp == t_ns {
        return Some(step);
    }
    let hz = st.physics_hz?;
    let ahead = ((t_ns as f64 - stamp as f64) / 1e9 * hz).round();
    (step as f64 + ahead >= 0.0).then_some((step as f64 + ahead) as u64)
}

fn take_perception(st: &mut State, frame: &PerceptionFrame, pub_ns: u64) {
    if st.perception_stamp_s.is_some_and(|p| frame.stamp_s < p) {
        tracing::debug!(stamp_s = frame.stamp_s, "perception older than the last one: ignored");
        return;
    }
    st.stats.perception_frames += 1;
    st.perception_overdue = false;
    st.perception_stamp_s = Some(frame.stamp_s);
    st.perception_pub_ns = Some(pub_ns);
    st.ctl.perceive(frame, &st.ego);
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ground_truth() -> AccSettings {
        AccSettings { perception: PerceptionSource::GroundTruth, ..AccSettings::default() }
    }

    /// The watchdog on an injected clock: no wall time passes in this test.
    #[test]
    fn the_watchdog_brakes_only_while_speed_is_older_than_its_limit() {
        let settings = ground_truth();
        let max_age = Duration::from_millis(settings.stale.speed_max_age_ms);
        let mut st = State::new(settings);
        let t0 = Instant::now();
        assert!(st.watchdog(t0 + max_age * 10, true).is_none(), "no speed yet: nothing to guard");

        st.ego = EgoNow { t_s: 1.0, speed_mps: 20.0, ..EgoNow::default() };
        st.last_speed_at = Some(t0);
        assert!(st.watchdog(t0 + max_age, true).is_none(), "fresh up to its age limit");
        let mut brakes = Vec::new();
        for i in 1..=20 {
            let a = st.watchdog(t0 + max_age + WATCHDOG_PERIOD * i, true).expect("stale speed: a command");
            assert_eq!(a.command.answers_step, None, "answers no step");
            assert_eq!(a.command.throttle, 0.0);
            assert_eq!(a.stamp_ns, 1_000_000_000, "stamped with the last speed's time");
            let status = a.status.expect("says why");
            assert_eq!(status.mode, AccMode::Stale);
            assert_eq!(status.warnings, [AccWarning::StaleSpeed]);
            brakes.push(a.command.brake);
        }
        assert!(brakes[19] > 0.0, "brakes: {brakes:?}");
        // The commands lead the target by the actuator lag's compensation; the brake the car
        // applies (the commands through that lag) only grows.
        let (lag, dt) = (st.ctl.settings().vehicle.actuator_lag_s, WATCHDOG_PERIOD.as_secs_f64());
        let applied: Vec<f64> = brakes
            .iter()
            .scan(0.0, |b, &c| {
                *b = slipstream_model::vehicle::lag_toward(*b, c as f64, lag, dt);
                Some(*b)
            })
            .collect();
        assert!(applied.windows(2).all(|w| w[1] >= w[0] - 1e-9), "brakes smoothly, never letting go: {applied:?}");
        assert_eq!(st.stats.watchdog_commands, 20);

        // A vanished detector is said too.
        let a = st.watchdog(t0 + max_age * 4, false).unwrap();
        assert!(a.status.unwrap().warnings.contains(&AccWarning::PerceptionLost));

        // Speed again: quiet until it ages once more.
        let t1 = t0 + Duration::from_secs(10);
        st.last_speed_at = Some(t1);
        assert!(st.watchdog(t1 + max_age / 2, true).is_none());
        assert!(st.watchdog(t1 + max_age * 2, true).is_some());
    }

    #[test]
    fn a_speed_message_is_answered_with_its_step_and_a_status_at_the_status_rate() {
        let mut st = State::new(AccSettings { status_hz: 20.0, ..ground_truth() });
        st.ego = EgoNow { t_s: 0.5, speed_mps: 20.0, ..EgoNow::default() };
        let first = st.answer(500_000_000, Some(50), true);
        assert_eq!(first.command.answers_step, Some(50));
        let status = first.status.expect("the first answer carries a status");
        assert!(status.warnings.contains(&AccWarning::StalePerception), "no perception yet: {status:?}");
        // The next step, 10 ms on, is inside the same 50 ms status period; 50 ms on is not.
        st.ego.t_s = 0.51;
        assert!(st.answer(510_000_000, Some(51), true).status.is_none());
        st.ego.t_s = 0.55;
        assert!(st.answer(550_000_000, Some(55), true).status.is_some());
        assert_eq!((st.stats.commands, st.stats.status), (3, 2));
    }
}
