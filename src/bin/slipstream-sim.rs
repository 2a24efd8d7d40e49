//! `slipstream-sim`: the driving simulator node. Parses the command line and calls
//! `slipstream::sim::run`.

use anyhow::{Context, Result};
use clap::Parser;
use slipstream::sim::args::{SimArgs, SimCli};

fn main() -> std::process::ExitCode {
    let cli = SimCli::parse();
    let json = cli.sim.json;
    slipstream::cli::node_exit_code(run(cli), json)
}

fn run(cli: SimCli) -> Result<()> {
    slipstream::cli::init_tracing(slipstream::cli::LogLevel::Node);
    if cli.sim.list_scenarios {
        print!("{}", SimArgs::scenario_list());
        return Ok(());
    }
    let settings = cli.sim.settings()?;
    let scenario = cli.sim.scenario()?;
    let seed = cli.sim.seed.unwrap_or(scenario.seed);
    let world = slipstream::sim::World::new(scenario, seed, settings.physics_hz);
    if let Some(path) = &cli.sim.preview {
        let (png, truth) = slipstream::sim::preview(world, &settings, cli.sim.at, true).context("sim: preview")?;
        std::fs::write(path, png).with_context(|| format!("write {}", path.display()))?;
        let in_view = truth.objects.iter().filter(|o| o.bbox.is_some()).count();
        println!("{}: step {}, {} vehicles, {in_view} in view", path.display(), truth.step, truth.objects.len());
        return Ok(());
    }
    slipstream::node::serve(&cli.connect, &cli.faults, &cli.sim.name, async |bus, shutdown| {
        let report = slipstream::sim::run(bus, world, &settings, shutdown).await.context("sim: run")?;
        // The summary first: nothing on the way out can lose it.
        if cli.sim.json {
            println!("{}", serde_json::to_string_pretty(&report)?);
        } else {
            println!("{}", report.summary());
        }
        anyhow::Ok(())
    })
}
