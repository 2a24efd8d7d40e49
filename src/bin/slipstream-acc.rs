//! `slipstream-acc`: adaptive cruise control on the bus. Parses the command line and calls
//! `slipstream::acc::node::run`.

use anyhow::{Context, Result};
use clap::Parser;
use slipstream::acc::args::AccCli;

fn main() -> std::process::ExitCode {
    let cli = AccCli::parse();
    let json = cli.json;
    slipstream::cli::node_exit_code(run(cli), json)
}

fn run(cli: AccCli) -> Result<()> {
    slipstream::cli::init_tracing(slipstream::cli::LogLevel::Node);
    let settings = cli.acc.settings()?;
    slipstream::node::serve(&cli.connect, &cli.faults, &cli.acc.name, async |bus, shutdown| {
        let stats = slipstream::acc::node::run(bus, settings, shutdown).await.context("acc: run")?;
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
        for input in stats.inputs.iter().filter(|i| i.injected_dropped + i.injected_delayed + i.injected_duplicated > 0)
        {
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
        anyhow::Ok(())
    })
}
