//! `slipstream-acc`: adaptive cruise control on the bus. Parses the command line and calls
//! `slipstream::acc::node::run`.

use anyhow::{Context, Result};
use clap::Parser;
use slipstream::acc::args::AccArgs;
use slipstream::config::{ConnectArgs, FaultArgs};

/// slipstream-acc: adaptive cruise control, closing the loop through the simulator.
///
/// Reads vehicle/speed, vehicle/state, the vehicles ahead (perception/objects, or the
/// simulator's ground truth with --perception ground-truth) and acc/command; publishes
/// vehicle/control for every speed message (naming the step it answers, for lockstep) and
/// acc/status (mode, set speed, target acceleration, lead, gap, desired gap, TTC, warnings).
/// Keeps a time gap to the lead in its lane, holds the set speed with nobody ahead, stops and
/// goes, warns and brakes hard when a collision threatens, and brakes smoothly when its inputs
/// go stale. Control law and results: docs/control.md. Examples:
///
///   slipstream-acc                                  (camera perception, config/acc.json5)
///
///   slipstream-acc --perception ground-truth --set-speed 30 --time-gap 2.0
///
///   slipstream-acc --lockstep     (with slipstream-sim --mode lockstep --wait-for acc)
#[derive(Parser)]
#[command(name = "slipstream-acc", version, verbatim_doc_comment)]
struct Cli {
    #[command(flatten)]
    connect: ConnectArgs,
    #[command(flatten)]
    faults: FaultArgs,
    #[command(flatten)]
    acc: AccArgs,
    /// At exit, print the run's statistics as JSON on stdout (commands, modes, and per input
    /// what arrived, was lost on the way, or was dropped or delayed by --faults)
    #[arg(long)]
    json: bool,
}

fn main() -> std::process::ExitCode {
    slipstream::cli::exit_code(run().map(|()| std::process::ExitCode::SUCCESS))
}

fn run() -> Result<()> {
    slipstream::cli::apply_zenoh_runtime_default();
    let cli = Cli::parse();
    slipstream::cli::init_tracing(slipstream::cli::LogLevel::Node);
    let settings = cli.acc.settings()?;
    let rt = tokio::runtime::Runtime::new()?;
    rt.block_on(async {
        let bus = slipstream::Bus::open_node(&cli.connect, &cli.faults, &cli.acc.name)
            .await
            .context("acc: join the bus")?;
        let shutdown = async {
            slipstream::cli::stop_requested().await;
        };
        let stats = slipstream::acc::node::run(&bus, settings, shutdown).await.context("acc: run")?;
        tracing::info!(
            "{} commands ({} from the watchdog), {} perception frames, {} stale episodes, {} emergencies, {} lockstep waits timed out, {} answers without their step's state",
            stats.commands,
            stats.watchdog_commands,
            stats.perception_frames,
            stats.stale_episodes,
            stats.emergencies,
            stats.lockstep_waits_timed_out,
            stats.state_waits_timed_out
        );
        for input in stats.inputs.iter().filter(|i| i.injected_dropped + i.injected_delayed + i.injected_duplicated > 0) {
            tracing::info!(
                "{}: {} arrived, {} lost on the way; injected: {} dropped, {} delayed, {} duplicated",
                input.topic,
                input.received,
                input.lost,
                input.injected_dropped,
                input.injected_delayed,
                input.injected_duplicated
            );
        }
        if cli.json {
            println!("{}", serde_json::to_string_pretty(&stats)?);
        }
        bus.leave().await;
        anyhow::Ok(())
    })
}
