//! The command route's I/O: a ROS 2 subscription (token and data key) whose samples go
//! through the [`CommandGate`], and a vehicle/speed subscription that sends the gate's
//! control on the bus once per speed message while a command is fresh.

use std::sync::Arc;

use crate::error::{Error, Result};
use parking_lot::Mutex;
use zenoh::liveliness::LivelinessToken;
use zenoh::sample::Sample;

use super::command::{CommandGate, CommandStats};
use super::error::Ros2Error;
use super::graph::Attachment;
use super::mapping::Entry;
use super::messages::{from_cdr, AckermannDriveStamped};
use super::node::RosNode;
use slipstream_contract::bus::{Bus, CallbackSubscriber, Publisher, Received};
use slipstream_contract::msg::{ControlCommand, Speed};
use slipstream_contract::topics;

/// ROS commands in, vehicle/control out.
pub struct CommandPath {
    gate: Arc<Mutex<CommandGate>>,
    _subscriber: zenoh::pubsub::Subscriber<()>,
    _token: LivelinessToken,
    _speed: CallbackSubscriber,
}

impl CommandPath {
    pub async fn start(
        bus: &Bus,
        node: &RosNode,
        entry: &Entry,
        vehicle: slipstream_model::vehicle::VehicleParams,
    ) -> Result<CommandPath> {
        let (key, token) = node.subscription(&entry.name, &entry.type_name, entry.qos).await?;
        let gate: Arc<Mutex<CommandGate>> = Arc::default();
        let g = gate.clone();
        let subscriber = node
            .session()
            .declare_subscriber(key.clone())
            .callback(move |sample: Sample| {
                let now = slipstream_contract::msg::wall_clock_ns();
                match read(&sample) {
                    Ok((gid, cmd)) => {
                        let _ = g.lock().offer(gid, now, &cmd.drive, &vehicle);
                    }
                    Err(why) => g.lock().refuse(now, &why),
                }
            })
            .await
            .map_err(Error::zenoh(format!("subscribe to ROS 2 commands on {key}")))?;
        let control: Publisher<ControlCommand> = bus.publisher(topics::VEHICLE_CONTROL).await?;
        let g = gate.clone();
        let speed = bus
            .subscribe_with(topics::VEHICLE_SPEED, move |s: Received<Speed>| {
                let command = g.lock().control(slipstream_contract::msg::wall_clock_ns(), s.msg.speed_mps, &vehicle);
                if let Some(c) = command {
                    match control.put(s.header.stamp_sim_ns, &c) {
                        Ok(_) => g.lock().stats.applied += 1,
                        Err(e) => tracing::warn!("vehicle/control: {e}"),
                    }
                }
            })
            .await?;
        tracing::info!(topic = %node.id.resolve(&entry.name), %key, "ROS 2 commands drive the ego");
        Ok(CommandPath { gate, _subscriber: subscriber, _token: token, _speed: speed })
    }

    pub fn stats(&self) -> CommandStats {
        self.gate.lock().stats.clone()
    }
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
