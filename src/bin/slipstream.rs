//! `slipstream`: the tools. Parses the command line and calls the library.

use anyhow::{Context, Result};
use clap::{Parser, Subcommand};
use slipstream::bench::{self, BenchArgs, CaseSpec};
use slipstream::config::ConnectArgs;

/// slipstream: a driving simulator, perception and cruise control glued by Zenoh.
///
/// Every command reads config/zenoh.json5 (or -c FILE) and config/slipstream.json5 (or
/// -t FILE) from the working directory when present, else built-in defaults: peer mode on
/// this machine, no router needed.
#[derive(Parser)]
#[command(version, propagate_version = true)]
struct Cli {
    #[command(flatten)]
    connect: ConnectArgs,
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Measure the bus against raw Zenoh, UDP and TCP (two processes on loopback; use --release)
    Bench(BenchArgs),
    /// Show the key of every topic after namespace and remapping, its QoS, and the Zenoh
    /// mode and endpoints in use
    Info {
        /// Print JSON instead of a table
        #[arg(long)]
        json: bool,
    },
    /// One side of a benchmark case (started by `slipstream bench`)
    #[command(hide = true)]
    BenchPeer {
        #[arg(value_parser = ["send", "recv"])]
        role: String,
        #[arg(long)]
        spec: String,
        #[arg(long)]
        endpoint: Option<String>,
    },
}

fn main() -> Result<()> {
    let cli = Cli::parse();
    slipstream::cli::init_tracing();
    match cli.command {
        Command::Bench(args) => {
            let report = bench::run(&args)?;
            let md = bench::markdown(&report);
            if args.json {
                println!("{}", serde_json::to_string_pretty(&report)?);
            } else {
                println!("{md}");
            }
            if let Some(path) = &args.markdown {
                std::fs::write(path, format!("Command: `{}`\n{md}", report.command))
                    .with_context(|| format!("write {}", path.display()))?;
            }
            Ok(())
        }
        Command::Info { json } => {
            let info = slipstream::tools::info::gather(&cli.connect)?;
            if json {
                println!("{}", serde_json::to_string_pretty(&info)?);
            } else {
                print!("{}", slipstream::tools::info::render(&info));
            }
            Ok(())
        }
        Command::BenchPeer { role, spec, endpoint } => {
            let spec: CaseSpec = serde_json::from_str(&spec).context("bench-peer: parse --spec")?;
            let rt = tokio::runtime::Runtime::new()?;
            rt.block_on(async move {
                match (role.as_str(), endpoint) {
                    ("send", Some(ep)) => bench::run_sender(spec, ep).await,
                    ("send", None) => anyhow::bail!("bench-peer send needs --endpoint"),
                    _ => bench::run_receiver(spec).await,
                }
            })
        }
    }
}
