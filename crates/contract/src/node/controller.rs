//! A controller of the user's own as one function, `control(ego, ahead, settings) -> an
//! acceleration` (or a [`Decision`]); [`run`] keeps the rest of docs/node-contract.md: it answers
//! every vehicle/state with a ControlCommand naming the state's step and copying its stamp,
//! waits on a step that brought a camera frame for that frame's objects (in lockstep as long as
//! slipstream-acc does, so a run repeats; briefly otherwise), turns the acceleration into pedals
//! through the vehicle sim/ego declares, publishes acc/status (what the judge reads) and
//! declares the liveliness token once it listens.
//!
//! examples/own-controller/src/main.rs is a whole node on it; its shape:
//!
//! ```text
//! let args = Args::parse();                      // your clap struct, NodeArgs flattened in
//! node::serve(&args.node.connect, &FaultArgs::default(), args.node.name_or("acc"), async |bus, stop| {
//!     let law = |ego: &Ego, ahead: &[Ahead], s: &DriverSettings| 0.5 * (s.set_speed_mps - ego.speed_mps);
//!     controller::run(bus, &args.node, law, stop).await
//! })
//! ```

use std::future::Future;
use std::time::Duration;

use serde::Serialize;

use super::args::NodeArgs;
use super::controller_inputs::{Inputs, Known};
pub use super::law::{Ahead, Decision, DriverSettings, Ego};
use crate::bus::{Bus, BusError, Publisher, StatsSnapshot};
use crate::msg::{AccMode, AccStatus, AccWarning, ControlCommand, LeadInfo, VehicleState};
use crate::topics;

/// How long an answer waits for its frame's objects (and the first for sim/ego and the camera's
/// rate): in lockstep as long as slipstream-acc's `lockstep_wait_ms`, so a run never depends on
/// timing; outside it briefly, then with the objects there are.
const LOCKSTEP_WAIT: Duration = Duration::from_secs(1);
const REALTIME_WAIT: Duration = Duration::from_millis(20);
/// acc/status per simulated second (slipstream-acc's default rate).
const STATUS_HZ: f64 = 20.0;
/// The gap kept at standstill, for acc/status's desired gap, m.
const STANDSTILL_GAP_M: f64 = 5.0;

/// What a run did.
#[derive(Debug, Clone, Default, Serialize)]
pub struct ControllerStats {
    /// vehicle/control messages, one per vehicle/state.
    pub answered: u64,
    /// Frame steps answered without that frame's objects (they did not come in time).
    pub frame_waits_timed_out: u64,
    /// The inputs' statistics at the end (received, lost on the way).
    pub inputs: Vec<StatsSnapshot>,
}

/// Runs `control` as the loop's controller until `shutdown` completes (see the module doc).
pub async fn run<D: Into<Decision>>(
    bus: &Bus,
    args: &NodeArgs,
    mut control: impl FnMut(&Ego, &[Ahead], &DriverSettings) -> D,
    shutdown: impl Future,
) -> Result<ControllerStats, BusError> {
    let states = bus.subscriber(topics::VEHICLE_STATE).await?;
    let inputs = Inputs::open(bus, args.ground_truth()).await?;
    if args.lockstep() {
        bus.keep_every_message();
    }
    let out = Outputs {
        control: bus.publisher(topics::VEHICLE_CONTROL).await?,
        status: bus.publisher(topics::ACC_STATUS).await?,
        status_tick: None,
    };
    // Listening now: the simulator in lockstep takes its first step when it sees the token.
    bus.announce().await?;
    let wait = if args.lockstep() { LOCKSTEP_WAIT } else { REALTIME_WAIT };
    let (mut known, mut stats, mut out) = (Known::default(), ControllerStats::default(), out);
    let mut latched_waited = false;
    tokio::pin!(shutdown);
    loop {
        let state = tokio::select! {
            s = states.recv() => s,
            _ = &mut shutdown => break,
        };
        if !std::mem::replace(&mut latched_waited, true) {
            inputs.latched(&mut known, LOCKSTEP_WAIT).await;
        }
        let (t_ns, step) = (state.header.stamp_sim_ns, state.msg.step);
        inputs.poll(&mut known);
        if known.physics_hz.is_none() && step > 0 && t_ns > 0 {
            known.physics_hz = Some((step as f64 * 1e9 / t_ns as f64).round());
        }
        if known.frame_due(step, t_ns) && !inputs.objects_at(&mut known, t_ns, wait).await {
            stats.frame_waits_timed_out += 1;
        }
        out.answer(t_ns, &ego_of(t_ns, &state.msg), &known, &mut control)?;
        stats.answered += 1;
    }
    stats.inputs = inputs.stats();
    stats.inputs.insert(0, states.stats().snapshot());
    Ok(stats)
}

fn ego_of(t_ns: u64, s: &VehicleState) -> Ego {
    Ego {
        t_s: t_ns as f64 / 1e9,
        step: s.step,
        speed_mps: s.speed_mps,
        accel_mps2: s.acceleration_in_body_mps2[0],
        yaw_rate_radps: s.yaw_rate_radps,
    }
}

/// The controller's publishers and the status clock.
struct Outputs {
    control: Publisher<ControlCommand>,
    status: Publisher<AccStatus>,
    status_tick: Option<i64>,
}

impl Outputs {
    /// The command answering the state of `ego.step` (stamped `stamp_ns`, copied), and
    /// acc/status when its tick is due.
    fn answer<D: Into<Decision>>(
        &mut self,
        stamp_ns: u64,
        ego: &Ego,
        known: &Known,
        control: &mut impl FnMut(&Ego, &[Ahead], &DriverSettings) -> D,
    ) -> Result<(), BusError> {
        let settings = &known.settings;
        let decision = match settings.enabled {
            true => control(ego, &known.ahead_of_bumper(), settings).into(),
            false => Decision::from(0.0),
        };
        let (throttle, brake) = match (settings.enabled, &settings.vehicle) {
            (false, _) => (0.0, 0.0),
            (true, Some(v)) => v.longitudinal().pedals_for(ego.speed_mps, decision.accel_mps2),
            // Before sim/ego: a rough car, so that a node started by hand still drives.
            (true, None) => ((decision.accel_mps2 / 3.0).clamp(0.0, 1.0), (-decision.accel_mps2 / 9.0).clamp(0.0, 1.0)),
        };
        let command = ControlCommand {
            throttle: throttle as f32,
            brake: brake as f32,
            steer: 0.0,
            answers_step: Some(ego.step),
            perception_stamp_pub_ns: known.ahead_pub_ns,
        };
        self.control.put(stamp_ns, &command)?;
        let tick = (ego.t_s * STATUS_HZ + 1e-9).floor() as i64;
        if self.status_tick != Some(tick) {
            self.status_tick = Some(tick);
            self.status.put(stamp_ns, &status(ego, settings, &decision))?;
        }
        Ok(())
    }
}

/// acc/status for a decision: the mode the judge reads, the lead followed.
fn status(ego: &Ego, settings: &DriverSettings, d: &Decision) -> AccStatus {
    let mode = match (settings.enabled, d.emergency, d.lead.is_some()) {
        (false, _, _) => AccMode::Off,
        (true, true, _) => AccMode::Emergency,
        (true, false, true) => AccMode::Follow,
        (true, false, false) => AccMode::Speed,
    };
    let lead = d.lead.map(|l| LeadInfo {
        id: l.id,
        gap_m: l.gap_m,
        desired_gap_m: STANDSTILL_GAP_M + settings.time_gap_s * ego.speed_mps,
        relative_speed_mps: l.relative_speed_mps,
        ttc_s: (l.relative_speed_mps < 0.0).then(|| l.gap_m / -l.relative_speed_mps),
    });
    AccStatus {
        mode,
        set_speed_mps: settings.set_speed_mps,
        time_gap_s: settings.time_gap_s,
        target_accel_mps2: d.accel_mps2,
        lead,
        warnings: if d.emergency { vec![AccWarning::ForwardCollision] } else { vec![] },
    }
}
