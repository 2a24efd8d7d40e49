//! `slipstream-detect`: vehicle detection and tracking on the bus. Parses the command line and
//! calls `slipstream::perception::node::run`.

use anyhow::{Context, Result};
use clap::Parser;
use slipstream::perception::args::DetectCli;
use slipstream::perception::DetectSettings;

fn main() -> std::process::ExitCode {
    let cli = DetectCli::parse();
    let json = cli.json;
    slipstream::cli::node_exit_code(run(cli), json)
}

fn run(cli: DetectCli) -> Result<()> {
    slipstream::cli::init_tracing(slipstream::cli::LogLevel::Node);
    let settings = DetectSettings::resolve(cli.settings.as_deref())?;
    slipstream::node::serve(&cli.connect, &cli.faults, &cli.name, async |bus, shutdown| {
        let stats = slipstream::perception::node::run(bus, settings, shutdown).await.context("detect: run")?;
        tracing::info!(
            "{} frames, {} skipped, {} unusable, {} before camera info, {} detections; {} with the narrow camera, {} without its frame",
            stats.frames,
            stats.skipped,
            stats.unusable,
            stats.without_info,
            stats.detections,
            stats.narrow_frames,
            stats.narrow_missing
        );
        if cli.json {
            println!("{}", serde_json::to_string_pretty(&stats)?);
        }
        anyhow::Ok(())
    })
}
