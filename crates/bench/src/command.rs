//! The bench's command lines: `slipstream bench` (the report, and its markdown file), and the
//! hidden `bench-peer` and `bench-fleet-watch` that the bench starts as child processes.

use std::process::ExitCode;

use anyhow::{Context, Result};

use super::{markdown, run, run_receiver, run_sender, BenchArgs, CaseSpec};

/// `slipstream bench`: runs the suites, prints the report (or JSON) and writes its markdown
/// to --markdown.
pub fn command(args: &BenchArgs) -> Result<ExitCode> {
    let report = run(args)?;
    let md = markdown(&report);
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        println!("{md}");
    }
    if let Some(path) = &args.markdown {
        std::fs::write(path, format!("Command: `{}`\n{md}", report.command))
            .with_context(|| format!("write {}", path.display()))?;
    }
    Ok(ExitCode::SUCCESS)
}

/// `bench-peer`: one side of a benchmark case.
#[derive(clap::Args)]
pub struct PeerArgs {
    #[arg(value_parser = ["send", "recv"])]
    pub role: String,
    /// The case, as JSON ([`CaseSpec`])
    #[arg(long)]
    pub spec: String,
    /// The receiver's endpoint(s) for a sender; the router's for a receiver through one
    #[arg(long)]
    pub endpoint: Vec<String>,
}

/// `bench-peer`: sends or receives the case until it is done.
pub fn peer(args: &PeerArgs) -> Result<ExitCode> {
    let spec: CaseSpec = serde_json::from_str(&args.spec).context("bench-peer: parse --spec")?;
    let rt = tokio::runtime::Runtime::new()?;
    rt.block_on(async move {
        match args.role.as_str() {
            "send" => run_sender(spec, args.endpoint.clone()).await,
            _ => run_receiver(spec, args.endpoint.first().cloned()).await,
        }
    })?;
    Ok(ExitCode::SUCCESS)
}

/// `bench-fleet-watch`: what the observer saw, as one JSON line.
pub fn fleet_watch(
    connect: &slipstream_contract::ConnectArgs,
    args: &super::fleet_watch::FleetWatchArgs,
) -> Result<ExitCode> {
    let rt = tokio::runtime::Runtime::new()?;
    let seen = rt.block_on(super::fleet_watch::watch(connect, args.clone()))?;
    println!("{}", serde_json::to_string(&seen)?);
    Ok(ExitCode::SUCCESS)
}
