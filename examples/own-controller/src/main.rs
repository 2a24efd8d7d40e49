//! A cruise controller of your own, in Rust, on slipstream's contract crate alone: one function
//! from the ego and what is ahead to an acceleration, run by the contract's node SDK
//! (`slipstream_contract::node::controller`), which keeps the rest of the node contract:
//! lockstep answers naming their step, stamps, the frame's objects awaited, acc/status, the
//! liveliness token, pedals through the vehicle sim/ego declares.
//!
//! ```sh
//! target/release/slipstream-sim --scenario steady-follow &
//! target/release/own-controller --set-speed 25
//! slipstream eval acc --perception ground-truth --controller target/release/own-controller
//! ```
//!
//! A teaching example of the interfaces (docs/own-node.md), not slipstream-acc: it holds the
//! set speed, or a time gap behind the nearest vehicle ahead in the ego's lane, whichever asks
//! for less, with no estimator and no emergency logic.

use std::time::Duration;

use clap::Parser;
use slipstream_contract::config::FaultArgs;
use slipstream_contract::node::controller::{self, Ahead, Decision, DriverSettings, Ego};
use slipstream_contract::node::{self, NodeArgs};

/// A cruise controller of your own on the slipstream bus (the contract crate alone).
#[derive(Debug, Parser)]
#[command(name = "own-controller", version)]
struct Args {
    /// The speed to hold with no vehicle ahead, m/s [default: the driver's, from sim/ego and
    /// acc/command]
    #[arg(long, value_parser = in_range(1.0, 70.0))]
    set_speed: Option<f64>,
    /// Stop after this many seconds (0: run until Ctrl-C or SIGTERM).
    #[arg(long, default_value_t = 0.0)]
    duration: f64,
    #[command(flatten)]
    node: NodeArgs,
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
/// The gap kept at standstill, m.
const STANDSTILL_GAP_M: f64 = 5.0;
/// Comfort limits of the acceleration asked for, m/s².
const MAX_ACCEL_MPS2: f64 = 2.0;
const MAX_DECEL_MPS2: f64 = -5.0;

/// The acceleration wanted: toward the set speed, or less to keep the time gap behind the
/// nearest vehicle ahead in the lane (a constant-time-gap law on gap and closing speed).
fn control(ego: &Ego, ahead: &[Ahead], settings: &DriverSettings, set_speed: Option<f64>) -> Decision {
    let mut accel = 0.4 * (set_speed.unwrap_or(settings.set_speed_mps) - ego.speed_mps);
    let lead = ahead
        .iter()
        .filter(|a| a.gap_m > 0.0 && a.lateral_m.abs() < LANE_HALF_WIDTH_M)
        .min_by(|a, b| a.gap_m.total_cmp(&b.gap_m))
        .copied();
    if let Some(l) = lead {
        let desired = STANDSTILL_GAP_M + settings.time_gap_s * ego.speed_mps;
        accel = accel.min(0.2 * (l.gap_m - desired) + 0.8 * l.relative_speed_mps);
    }
    Decision { accel_mps2: accel.clamp(MAX_DECEL_MPS2, MAX_ACCEL_MPS2), lead, emergency: false }
}

fn main() -> std::process::ExitCode {
    let args = Args::parse();
    let name = args.node.name_or("own-controller").to_string();
    let run = node::serve(&args.node.connect, &FaultArgs::default(), &name, async |bus, stop| {
        // One stop for the whole run: a signal, or the duration asked for.
        let stop = async {
            match args.duration > 0.0 {
                true => tokio::select! {
                    _ = stop => {},
                    _ = tokio::time::sleep(Duration::from_secs_f64(args.duration)) => {},
                },
                false => stop.await,
            }
        };
        let law = |ego: &Ego, ahead: &[Ahead], s: &DriverSettings| control(ego, ahead, s, args.set_speed);
        controller::run(bus, &args.node, law, stop).await.map_err(Box::<dyn std::error::Error>::from)
    });
    match run {
        Ok(stats) => {
            println!("{name}: {} commands sent", stats.answered);
            std::process::ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("Error: {e}");
            std::process::ExitCode::FAILURE
        }
    }
}
