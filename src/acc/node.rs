//! slipstream-acc on the bus: vehicle/speed + vehicle/state + perception (perception/objects,
//! or objects for ground truth) + acc/command -> vehicle/control (one per speed message, naming
//! the step it answers) and acc/status.
//!
//! Input health, checked at every speed message and by a wall-clock watchdog:
//! - perception older than `stale.perception_max_age_ms` of simulated time (header stamps),
//!   or the detector's liveliness token gone: StalePerception / PerceptionLost;
//! - no vehicle/speed for `stale.speed_max_age_ms` of wall time: StaleSpeed, and the watchdog
//!   keeps publishing braking commands (answering no step) until speed returns.
//!
//! Any of them puts the controller in Stale mode (throttle off, smooth braking); it recovers
//! by itself when fresh data return.

use std::future::Future;
use std::time::{Duration, Instant};

use serde::Serialize;

use super::controller::{Controller, EgoNow, PerceptionFrame};
use super::settings::{AccSettings, PerceptionSource};
use crate::bus::{Bus, BusError, NodeWatch, Received, Subscriber};
use crate::msg::{AccMode, AccWarning, ControlCommand, Detections, GroundTruthObjects, VehicleState};
use crate::topics;

/// What a run did.
#[derive(Debug, Clone, Default, Serialize)]
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
    /// Lockstep steps whose perception did not come within lockstep_wait_ms.
    pub lockstep_waits_timed_out: u64,
}

/// The perception input, by source.
enum PerceptionSub {
    Camera(Subscriber<Detections>),
    GroundTruth(Subscriber<GroundTruthObjects>),
}

impl PerceptionSub {
    /// The next perception message, converted, with its header.stamp_pub_ns.
    fn frame(&self, timeout: Option<Duration>) -> impl Future<Output = Option<(PerceptionFrame, u64)>> + '_ {
        async move {
            let convert_d = |r: Received<Detections>| {
                (PerceptionFrame::from_detections(r.header.stamp_sim_ns as f64 / 1e9, &r.msg), r.header.stamp_pub_ns)
            };
            let convert_g = |r: Received<GroundTruthObjects>| {
                (PerceptionFrame::from_ground_truth(r.header.stamp_sim_ns as f64 / 1e9, &r.msg), r.header.stamp_pub_ns)
            };
            match (self, timeout) {
                (PerceptionSub::Camera(s), None) => s.try_recv().map(convert_d),
                (PerceptionSub::Camera(s), Some(t)) => s.recv_timeout(t).await.map(convert_d),
                (PerceptionSub::GroundTruth(s), None) => s.try_recv().map(convert_g),
                (PerceptionSub::GroundTruth(s), Some(t)) => s.recv_timeout(t).await.map(convert_g),
            }
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

struct State {
    ctl: Controller,
    ego: EgoNow,
    /// The newest vehicle/state: its stamp and step.
    state: Option<(u64, u64)>,
    /// Physics rate learned from vehicle/state (steps per simulated second).
    physics_hz: Option<f64>,
    perception_stamp_s: Option<f64>,
    /// header.stamp_pub_ns of the newest perception message taken (traced in vehicle/control).
    perception_pub_ns: Option<u64>,
    camera_rate_hz: Option<f64>,
    info_waited: bool,
    last_speed_at: Option<Instant>,
    mode: Option<AccMode>,
    status_tick: Option<i64>,
    stats: AccStats,
    lockstep_log: Every,
}

/// Runs until `shutdown` completes.
pub async fn run(bus: &Bus, settings: AccSettings, shutdown: impl Future<Output = ()>) -> Result<AccStats, BusError> {
    let speed_sub = bus.subscriber(topics::VEHICLE_SPEED).await?;
    let state_sub = bus.subscriber(topics::VEHICLE_STATE).await?;
    let command_sub = bus.subscriber(topics::ACC_COMMAND).await?;
    let info_sub = bus.subscriber(topics::CAMERA_FRONT_INFO).await?;
    let perception = match settings.perception {
        PerceptionSource::Camera => PerceptionSub::Camera(bus.subscriber(topics::PERCEPTION_OBJECTS).await?),
        PerceptionSource::GroundTruth => PerceptionSub::GroundTruth(bus.subscriber(topics::OBJECTS).await?),
    };
    let detector: Option<NodeWatch> = match settings.perception {
        PerceptionSource::Camera => Some(bus.watch_node(&settings.perception_node).await?),
        PerceptionSource::GroundTruth => None,
    };
    let control_pub = bus.publisher(topics::VEHICLE_CONTROL).await?;
    let status_pub = bus.publisher(topics::ACC_STATUS).await?;
    tracing::info!(
        perception = ?settings.perception,
        lockstep = settings.lockstep,
        set_speed_mps = settings.set_speed_mps,
        time_gap_s = settings.time_gap_s,
        "acc up; waiting for vehicle/speed"
    );

    let speed_max_age = Duration::from_millis(settings.stale.speed_max_age_ms);
    let mut st = State {
        ctl: Controller::new(settings.clone()),
        ego: EgoNow::default(),
        state: None,
        physics_hz: None,
        perception_stamp_s: None,
        perception_pub_ns: None,
        camera_rate_hz: None,
        info_waited: false,
        last_speed_at: None,
        mode: None,
        status_tick: None,
        stats: AccStats::default(),
        lockstep_log: Every::new(Duration::from_secs(5)),
    };
    let mut watchdog = tokio::time::interval(Duration::from_millis(50));
    watchdog.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Skip);
    tokio::pin!(shutdown);
    loop {
        let speed = tokio::select! {
            _ = &mut shutdown => break,
            s = speed_sub.recv() => s,
            _ = watchdog.tick() => {
                let stale = st.last_speed_at.is_some_and(|t| t.elapsed() > speed_max_age);
                if stale {
                    // Simulated time moves on with the wall clock as far as the ACC can tell.
                    let since = st.last_speed_at.map_or(0.0, |t| t.elapsed().as_secs_f64());
                    let ego = EgoNow { t_s: st.ego.t_s + since, ..st.ego };
                    let detector_ok = detector.as_ref().is_none_or(|d| d.is_alive());
                    let mut warnings = vec![AccWarning::StaleSpeed];
                    if !detector_ok {
                        warnings.push(AccWarning::PerceptionLost);
                    }
                    let out = st.ctl.step(&ego, &warnings);
                    note_mode(&mut st, out.status.mode, &out.status.warnings);
                    let cmd = ControlCommand {
                        throttle: out.throttle,
                        brake: out.brake,
                        steer: 0.0,
                        answers_step: None,
                        perception_stamp_pub_ns: st.perception_pub_ns,
                    };
                    control_pub.put(st.ego_stamp_ns(), &cmd)?;
                    status_pub.put(st.ego_stamp_ns(), &out.status)?;
                    st.stats.watchdog_commands += 1;
                    st.stats.status += 1;
                }
                continue;
            }
        };
        st.last_speed_at = Some(Instant::now());
        let t_ns = speed.header.stamp_sim_ns;
        let t_s = t_ns as f64 / 1e9;

        // The state of this step (published right after the speed).
        let mut state = drain_states(&state_sub, &mut st);
        if st.state.is_none_or(|(stamp, _)| stamp < t_ns) {
            let deadline = Instant::now() + Duration::from_millis(20);
            while st.state.is_none_or(|(stamp, _)| stamp < t_ns) {
                let left = deadline.saturating_duration_since(Instant::now());
                match state_sub.recv_timeout(left).await {
                    Some(r) => {
                        take_state(&mut st, &r);
                        state = Some(r.msg);
                    }
                    None => break,
                }
            }
        }
        let answers_step = answers_step(&st, t_ns);
        st.ego = EgoNow {
            t_s,
            speed_mps: speed.msg.speed_mps,
            accel_mps2: state.as_ref().map_or(st.ego.accel_mps2, |s| s.acceleration_in_body_mps2[0]),
            yaw_rate_radps: state.as_ref().map_or(st.ego.yaw_rate_radps, |s| s.yaw_rate_radps),
        };

        while let Some(c) = command_sub.try_recv() {
            if let Some(note) = st.ctl.command(&c.msg) {
                tracing::warn!("acc/command: {note}");
            }
        }
        while let Some(info) = info_sub.try_recv() {
            st.camera_rate_hz = Some(info.msg.rate_hz);
        }
        if settings.lockstep && st.camera_rate_hz.is_none() && !st.info_waited {
            // Which steps bring a frame follows from the camera rate: wait for the (latched)
            // camera info once, or a frame answered a step late makes the run differ.
            st.info_waited = true;
            match info_sub.recv_timeout(Duration::from_millis(settings.lockstep_wait_ms)).await {
                Some(info) => st.camera_rate_hz = Some(info.msg.rate_hz),
                None => tracing::warn!(
                    waited_ms = settings.lockstep_wait_ms,
                    "lockstep: no camera/front/info; perception is awaited only for the first frame"
                ),
            }
        }
        while let Some((frame, pub_ns)) = perception.frame(None).await {
            take_perception(&mut st, &frame, pub_ns);
        }
        let have = |st: &State| st.perception_stamp_s.is_some_and(|p| p >= t_s - 1e-9);
        if settings.lockstep && st.frame_expected_at(t_s) && !have(&st) {
            let deadline = Instant::now() + Duration::from_millis(settings.lockstep_wait_ms);
            let mut arrived = false;
            while Instant::now() < deadline {
                let left = deadline.saturating_duration_since(Instant::now());
                if let Some((frame, pub_ns)) = perception.frame(Some(left)).await {
                    take_perception(&mut st, &frame, pub_ns);
                    arrived = have(&st);
                    if arrived {
                        break;
                    }
                }
            }
            if !arrived {
                st.stats.lockstep_waits_timed_out += 1;
                if let Some(more) = st.lockstep_log.ready() {
                    tracing::warn!(
                        t_s,
                        waited_ms = settings.lockstep_wait_ms,
                        suppressed = more,
                        "lockstep: no perception for the frame at this step; answering with what there is (is the detector running?)"
                    );
                }
            }
        }

        let mut warnings = Vec::new();
        let max_age = settings.stale.perception_max_age_ms as f64 / 1e3;
        if st.perception_stamp_s.is_none_or(|p| t_s - p > max_age) {
            warnings.push(AccWarning::StalePerception);
        }
        if detector.as_ref().is_some_and(|d| !d.is_alive()) {
            warnings.push(AccWarning::PerceptionLost);
        }
        let out = st.ctl.step(&st.ego, &warnings);
        note_mode(&mut st, out.status.mode, &out.status.warnings);
        let cmd = ControlCommand {
            throttle: out.throttle,
            brake: out.brake,
            steer: 0.0,
            answers_step,
            perception_stamp_pub_ns: st.perception_pub_ns,
        };
        control_pub.put(t_ns, &cmd)?;
        st.stats.commands += 1;
        // Up to date from here: time spent waiting above (lockstep) does not age the speed.
        st.last_speed_at = Some(Instant::now());
        let tick = (t_s * settings.status_hz + 1e-9).floor() as i64;
        if st.status_tick != Some(tick) {
            st.status_tick = Some(tick);
            status_pub.put(t_ns, &out.status)?;
            st.stats.status += 1;
        }
    }
    Ok(st.stats)
}

impl State {
    fn ego_stamp_ns(&self) -> u64 {
        (self.ego.t_s * 1e9) as u64
    }

    /// Whether a camera frame (and so a perception message) is due at simulated time `t_s`:
    /// the simulator's own rule (`sim::node::due`) with the camera rate from camera/front/info
    /// and the physics rate learned from vehicle/state.
    fn frame_expected_at(&self, t_s: f64) -> bool {
        match (self.camera_rate_hz, self.physics_hz) {
            (Some(rate), Some(hz)) => {
                let hz = hz.round().max(1.0);
                crate::sim::node::due((t_s * hz).round() as u64, rate, hz as u32)
            }
            // Before the rates are known: the first frame comes with step 0.
            _ => self.perception_stamp_s.is_none(),
        }
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
        take_state(st, &r);
        newest = Some(r.msg);
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
    (step as f64 + ahead >= 0.0).then(|| (step as f64 + ahead) as u64)
}

fn take_perception(st: &mut State, frame: &PerceptionFrame, pub_ns: u64) {
    if st.perception_stamp_s.is_some_and(|p| frame.stamp_s < p) {
        tracing::debug!(stamp_s = frame.stamp_s, "perception older than the last one: ignored");
        return;
    }
    st.stats.perception_frames += 1;
    st.perception_stamp_s = Some(frame.stamp_s);
    st.perception_pub_ns = Some(pub_ns);
    st.ctl.perceive(frame, &st.ego);
}

fn note_mode(st: &mut State, mode: AccMode, warnings: &[AccWarning]) {
    if st.mode == Some(mode) {
        return;
    }
    match mode {
        AccMode::Stale => {
            st.stats.stale_episodes += 1;
            tracing::warn!(?warnings, "inputs stale: throttle released, braking smoothly");
        }
        AccMode::Emergency => st.stats.emergencies += 1,
        _ => {
            if st.mode == Some(AccMode::Stale) {
                tracing::info!(?mode, "fresh inputs again: control resumed");
            } else {
                tracing::debug!(?mode, "mode");
            }
        }
    }
    st.mode = Some(mode);
}
