//! The command route's I/O: a ROS 2 subscription (token and data key) whose samples go
//! through the [`CommandGate`]. In realtime and fast runs a vehicle/speed subscription sends
//! the gate's control on the bus once per speed message while a command is fresh; in
//! lockstep each accepted command answers the vehicle/state its stamp names
//! ([`super::lockstep`]) at once, or when that state reaches the bridge if the command came
//! first, so the simulator's step waits for the ROS controller itself.

use std::sync::Arc;

use crate::error::{Error, Result};
use parking_lot::Mutex;
use zenoh::liveliness::LivelinessToken;
use zenoh::sample::Sample;

use super::command::{acceleration, control, CommandGate, CommandStats};
use super::graph::Attachment;
use super::lockstep::{Answer, Awaited, StepAnswers};
use super::mapping::Entry;
use super::messages::{from_cdr, AckermannDriveStamped};
use super::node::RosNode;
use super::status::StatusOut;
use crate::message_error::Ros2Error;
use slipstream_contract::bus::{Bus, CallbackSubscriber, Publisher, Received};
use slipstream_contract::msg::{wall_clock_ns, ControlCommand, Speed, VehicleState};
use slipstream_contract::topics;
use slipstream_model::vehicle::VehicleParams;

/// ROS commands in, vehicle/control out.
pub(crate) struct CommandPath {
    gate: Arc<Mutex<CommandGate>>,
    _subscriber: zenoh::pubsub::Subscriber<()>,
    _token: LivelinessToken,
    _loop_side: CallbackSubscriber,
}

impl CommandPath {
    /// Subscribes to the ROS commands of `entry` and sends them on as vehicle/control: per
    /// speed message, or, with `lockstep`, as the answer to the state each one names.
    pub(crate) async fn start(
        bus: &Bus,
        node: &RosNode,
        entry: &Entry,
        vehicle: VehicleParams,
        lockstep: bool,
    ) -> Result<CommandPath> {
        let (key, token) = node.subscription(&entry.name, &entry.type_name, entry.qos).await?;
        let gate: Arc<Mutex<CommandGate>> = Arc::default();
        let control: Arc<Publisher<ControlCommand>> = Arc::new(bus.publisher(topics::VEHICLE_CONTROL).await?);
        let answers: Arc<Mutex<StepAnswers<AckermannDriveStamped>>> = Arc::default();
        let status = Arc::new(StatusOut::start(bus).await?);
        let (g, a, c, st) = (gate.clone(), answers.clone(), control.clone(), status.clone());
        let subscriber = node
            .session()
            .declare_subscriber(key.clone())
            .callback(move |sample: Sample| {
                let now = wall_clock_ns();
                let cmd = match read(&sample) {
                    Ok((gid, cmd)) if g.lock().offer(gid, now, &cmd.drive, &vehicle).is_ok() => cmd,
                    Ok(_) => return,
                    Err(why) => return g.lock().refuse(now, &why),
                };
                if lockstep {
                    let verdict = a.lock().answer(cmd.header.stamp, cmd);
                    send(&g, (&c, &st), &vehicle, now, verdict);
                }
            })
            .await
            .map_err(Error::zenoh(format!("subscribe to ROS 2 commands on {key}")))?;
        let loop_side = match lockstep {
            true => await_states(bus, answers, (gate.clone(), control, status), vehicle).await?,
            false => per_speed(bus, gate.clone(), (control, status), vehicle).await?,
        };
        tracing::info!(topic = %node.id.resolve(&entry.name), %key, lockstep, "ROS 2 commands drive the ego");
        Ok(CommandPath { gate, _subscriber: subscriber, _token: token, _loop_side: loop_side })
    }

    pub(crate) fn stats(&self) -> CommandStats {
        self.gate.lock().stats.clone()
    }
}

/// Realtime and fast: the latest fresh command, applied at each vehicle/speed.
async fn per_speed(
    bus: &Bus,
    gate: Arc<Mutex<CommandGate>>,
    (control, status): (Arc<Publisher<ControlCommand>>, Arc<StatusOut>),
    vehicle: VehicleParams,
) -> Result<CallbackSubscriber> {
    Ok(bus
        .subscribe_with(topics::VEHICLE_SPEED, move |s: Received<Speed>| {
            let (now, speed) = (wall_clock_ns(), s.msg.speed_mps);
            let Some(c) = gate.lock().control(now, speed, &vehicle) else { return };
            match control.put(s.header.stamp_sim_ns, &c) {
                Ok(_) => gate.lock().stats.applied += 1,
                Err(e) => tracing::warn!("vehicle/control: {e}"),
            }
            if let Some(d) = gate.lock().latest() {
                status.sent(s.header.stamp_sim_ns, acceleration(&d, speed));
            }
        })
        .await?)
}

/// Lockstep: every vehicle/state awaits the command stamped with its time, or is answered by
/// one that came before it.
async fn await_states(
    bus: &Bus,
    answers: Arc<Mutex<StepAnswers<AckermannDriveStamped>>>,
    (gate, control, status): (Arc<Mutex<CommandGate>>, Arc<Publisher<ControlCommand>>, Arc<StatusOut>),
    vehicle: VehicleParams,
) -> Result<CallbackSubscriber> {
    Ok(bus
        .subscribe_with(topics::VEHICLE_STATE, move |s: Received<VehicleState>| {
            let (step, stamp_sim_ns, speed_mps) = (s.msg.step, s.header.stamp_sim_ns, s.msg.speed_mps);
            let verdicts = answers.lock().state(Awaited { step, stamp_sim_ns, speed_mps });
            for verdict in verdicts {
                send(&gate, (&control, &status), &vehicle, wall_clock_ns(), verdict);
            }
        })
        .await?)
}

/// Lockstep: a command that answers a state sent on as vehicle/control naming it; one that
/// answers none refused; one held for its state waits.
fn send(
    gate: &Mutex<CommandGate>,
    (control_out, status): (&Publisher<ControlCommand>, &StatusOut),
    vehicle: &VehicleParams,
    now: u64,
    verdict: Answer<AckermannDriveStamped>,
) {
    let (state, cmd) = match verdict {
        Answer::Now(state, cmd) => (state, cmd),
        Answer::Held => return,
        Answer::Refused(none) => return gate.lock().refuse(now, &none),
    };
    let mut c = control(&cmd.drive, state.speed_mps, vehicle);
    c.answers_step = Some(state.step);
    match control_out.put(state.stamp_sim_ns, &c) {
        Ok(_) => gate.lock().stats.applied += 1,
        Err(e) => tracing::warn!("vehicle/control: {e}"),
    }
    status.sent(state.stamp_sim_ns, acceleration(&cmd.drive, state.speed_mps));
}

/// The publisher's gid and the command of one sample.
fn read(sample: &Sample) -> Result<([u8; 16], AckermannDriveStamped), Ros2Error> {
    let attachment = sample
        .attachment()
        .ok_or(Ros2Error::Attachment("none: not an rmw_zenoh publisher".into()))
        .and_then(Attachment::from_zbytes)?;
    let cmd = from_cdr::<AckermannDriveStamped>(&sample.payload().to_bytes())?;
    Ok((attachment.source_gid, cmd))
}
