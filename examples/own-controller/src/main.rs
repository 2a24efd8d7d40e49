//! A cruise controller of your own, in Rust, on slipstream's contract crate alone: it reads
//! vehicle/speed and the simulator's objects and publishes vehicle/control, as slipstream-acc
//! does, so the simulator drives with it in slipstream-acc's place.
//!
//! ```sh
//! target/release/slipstream-sim --scenario steady-follow &
//! target/release/own-controller --set-speed 25
//! ```
//!
//! A teaching example of the interfaces (docs/own-node.md), not slipstream-acc: it holds the
//! set speed, or a time gap behind the nearest vehicle ahead in the ego's lane, whichever asks
//! for less, with no estimator and no emergency logic.

use std::time::Duration;

use clap::Parser;
use slipstream_contract::config::FaultArgs;
use slipstream_contract::msg::{ControlCommand, GroundTruthObjects};
use slipstream_contract::{process, topics, Bus, ConnectArgs};

/// A cruise controller of your own on the slipstream bus (the contract crate alone).
#[derive(Debug, Parser)]
#[command(name = "own-controller", version)]
struct Args {
    /// The speed to hold with no vehicle ahead, m/s.
    #[arg(long, default_value_t = 25.0, value_parser = in_range(1.0, 70.0))]
    set_speed: f64,
    /// The time gap to keep behind a vehicle ahead, s.
    #[arg(long, default_value_t = 1.8, value_parser = in_range(0.5, 5.0))]
    time_gap: f64,
    /// The node name (liveliness token nodes/NAME, and the attachment of each command).
    #[arg(long, default_value = "own-controller")]
    name: String,
    /// Stop after this many seconds (0: run until Ctrl-C or SIGTERM).
    #[arg(long, default_value_t = 0.0)]
    duration: f64,
    #[command(flatten)]
    connect: ConnectArgs,
}

/// A float flag checked against its range, with the range in the error.
fn in_range(lo: f64, hi: f64) -> impl Fn(&str) -> Result<f64, String> + Clone {
    move |s| match s.parse::<f64>() {
        Ok(v) if (lo..=hi).contains(&v) => Ok(v),
        Ok(v) => Err(format!("{v} is outside {lo}..{hi}")),
        Err(e) => Err(e.to_string()),
    }
}

/// Half a lane: a vehicle whose centre is nearer than this to the ego's axis is in its lane.
const LANE_HALF_WIDTH_M: f64 = 1.75;
/// The ego's origin (its rear axle) to its front bumper, for the gap bumper to bumper.
const FRONT_OVERHANG_M: f64 = 3.65;
/// The gap kept at standstill, m.
const STANDSTILL_GAP_M: f64 = 5.0;
/// Acceleration the pedals give at full travel, m/s²: a rough inverse of the vehicle model,
/// enough for a teaching controller (slipstream-acc inverts the shared vehicle model).
const FULL_THROTTLE_MPS2: f64 = 4.0;
const FULL_BRAKE_MPS2: f64 = 9.0;

/// The acceleration wanted at `speed` behind `lead` (gap m, relative speed m/s), m/s².
fn wanted_accel(speed: f64, lead: Option<(f64, f64)>, args: &Args) -> f64 {
    let mut accel = 0.4 * (args.set_speed - speed);
    if let Some((gap, relative_speed)) = lead {
        let desired = STANDSTILL_GAP_M + args.time_gap * speed;
        accel = accel.min(0.2 * (gap - desired) + 0.8 * relative_speed);
    }
    accel.clamp(-5.0, 2.0)
}

/// The gap (bumper to bumper) and relative speed of the nearest vehicle ahead in the ego's lane.
fn lead_of(objects: &GroundTruthObjects) -> Option<(f64, f64)> {
    objects
        .objects
        .iter()
        .filter(|o| o.position_in_ego_m[0] > 0.0 && o.position_in_ego_m[1].abs() < LANE_HALF_WIDTH_M)
        .min_by(|a, b| a.position_in_ego_m[0].total_cmp(&b.position_in_ego_m[0]))
        .map(|o| (o.position_in_ego_m[0] - FRONT_OVERHANG_M, o.velocity_in_ego_mps[0]))
}

/// Throttle and brake for an acceleration.
fn pedals(accel: f64) -> ControlCommand {
    let throttle = (accel / FULL_THROTTLE_MPS2).clamp(0.0, 1.0) as f32;
    let brake = (-accel / FULL_BRAKE_MPS2).clamp(0.0, 1.0) as f32;
    ControlCommand { throttle, brake, ..ControlCommand::NEUTRAL }
}

/// Drives until asked to stop: a command for every speed message, from the latest objects.
async fn drive(bus: &Bus, args: &Args) -> Result<u64, Box<dyn std::error::Error>> {
    let speed = bus.subscriber(topics::VEHICLE_SPEED).await?;
    let objects = bus.subscriber(topics::OBJECTS).await?;
    let control = bus.publisher(topics::VEHICLE_CONTROL).await?;
    // Listening now: let the loop see this node (a simulator in lockstep waits for it).
    bus.announce().await?;
    let (mut lead, mut sent) = (None, 0);
    // One stop and one deadline for the whole run, not a timer per speed message.
    let stop = process::stop_requested();
    let deadline = async {
        if args.duration > 0.0 {
            tokio::time::sleep(Duration::from_secs_f64(args.duration)).await
        } else {
            std::future::pending().await
        }
    };
    tokio::pin!(stop, deadline);
    loop {
        let s = tokio::select! {
            s = speed.recv() => s,
            _ = &mut stop => break,
            _ = &mut deadline => break,
        };
        while let Some(o) = objects.try_recv() {
            lead = lead_of(&o.msg);
        }
        let command = pedals(wanted_accel(s.msg.speed_mps, lead, args));
        control.put(s.header.stamp_sim_ns, &command)?;
        sent += 1;
    }
    Ok(sent)
}

fn main() -> std::process::ExitCode {
    // Zenoh's thread layout of every slipstream node, before any thread starts.
    process::apply_zenoh_runtime_default();
    let args = Args::parse();
    let run = async {
        let bus = Bus::open_node(&args.connect, &FaultArgs::default(), &args.name).await?;
        let sent = drive(&bus, &args).await;
        bus.leave().await;
        sent
    };
    match tokio::runtime::Runtime::new().map_err(Into::into).and_then(|rt| rt.block_on(run)) {
        Ok(sent) => {
            println!("{}: {sent} commands sent", args.name);
            std::process::ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("Error: {e}");
            std::process::ExitCode::FAILURE
        }
    }
}
