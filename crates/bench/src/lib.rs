//! `slipstream bench`: the bus against raw Zenoh, UDP and TCP, two processes on loopback, in
//! one run so every ratio compares figures taken on the same machine at the same time.
//!
//! Each case starts a receiver and a sender as child processes (`slipstream bench-peer`),
//! so a case can give both its own environment (ZENOH_RUNTIME) and nothing is shared but the
//! loopback interface. The receiver timestamps arrival against the publish time in the
//! message: one-way latency on one host's clock.
//!
//! By concern: command.rs (the command lines), cases.rs (the point-to-point cases under typed ids), child.rs (the processes),
//! figures.rs (runs to rows), ratios.rs, report.rs (JSON and markdown); the suites with
//! tables of their own in sim.rs, scale.rs, growth.rs, fleet.rs and nodes.rs.

mod cases;
mod child;
pub mod command;
mod egos;
mod figures;
mod fleet;
pub mod fleet_watch;
mod growth;
mod netns;
mod nodes;
mod peer;
mod plot;
mod ratios;
mod report;
mod scale;
mod sim;
mod spec;

use anyhow::{Context, Result};

pub use cases::{CaseId, FrameSize, Path, Phase, Table};
pub(crate) use child::{process_cpu_s, process_peak_rss_mib};
use child::{python_available, remove_seed_script, run_case, run_groups, PYTHON};
use figures::Latencies;
pub use figures::{median, Row};
pub use fleet::{FleetRow, RouterLoad};
pub use growth::{FanoutPath, FanoutRow, RouterRow};
pub use nodes::NodesRow;
pub(crate) use peer::{run_receiver, run_sender};
pub use ratios::Ratio;
pub use report::{markdown, BenchReport};
pub use scale::ScaleRow;
pub use sim::SimFigure;
pub(crate) use spec::CaseSpec;
pub use spec::{Background, Payload};

#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Suite {
    /// a. speed-size messages at 100 Hz: one-way latency per path
    Speed,
    /// b. 640x480 and 1280x720 RGB frames: frames/s, MB/s, one-way latency
    Frames,
    /// c. speed latency and losses while frames load the link
    Contention,
    /// d. the simulator: physics steps/s, render time per frame, fast-mode real-time factor
    Sim,
    /// e. complete loops side by side in realtime (1, 2, 4, 8): real-time factor, loop
    /// latency, CPU per loop; only when named (it loads the whole machine for minutes)
    Scale,
    /// f. camera fan-out: 640x480 frames to 1, 2, 4, 8 subscribers, in shared memory and
    /// through a router: frames/s and latency per subscriber
    Fanout,
    /// g. a router forwarding speed + control for 1-64 vehicles (--vehicles): messages/s,
    /// added latency, the router's CPU and memory
    Router,
    /// h. a fleet through capped links: N simulators on one host, their detectors and ACCs on
    /// another, a router between, every link capped (network namespaces, tc tbf; root);
    /// frames delivered, speed and control lost, loop latency, router CPU; only when named
    Fleet,
    /// i. a controller of your own against slipstream-acc: the same 10-run `eval sweep`
    /// (ground truth, one run at a time) with slipstream-acc, the Python SDK's example and the
    /// Rust SDK's: sweep wall time and the per-step cost each adds in lockstep; only when named
    Nodes,
}

#[derive(Debug, Clone, clap::Args)]
pub struct BenchArgs {
    /// Which suites to run [default: all]
    #[arg(value_enum)]
    pub suites: Vec<Suite>,
    /// Runs per case; figures are medians over runs
    #[arg(long, default_value_t = 3)]
    pub repeat: usize,
    /// Few messages and one run: checks that every path works (a smoke test, not figures)
    #[arg(long)]
    pub quick: bool,
    /// Print the results as JSON on stdout instead of the table
    #[arg(long)]
    pub json: bool,
    /// Also write the table (markdown) to this file
    #[arg(long, value_name = "FILE")]
    pub markdown: Option<std::path::PathBuf>,
    /// scale: how many complete loops side by side, in turn
    #[arg(long, value_delimiter = ',', default_value = "1,2,4,8,12,16")]
    pub loops: Vec<usize>,
    /// scale: simulated (= wall) seconds each batch of loops runs
    #[arg(long, default_value_t = 20.0)]
    pub scale_seconds: f64,
    /// fanout: how many subscribers, in turn
    #[arg(long, value_delimiter = ',', default_value = "1,2,4,8")]
    pub subscribers: Vec<usize>,
    /// router: how many vehicles, in turn (1 to 64)
    #[arg(long, value_delimiter = ',', default_value = "1,2,4,8,16")]
    pub vehicles: Vec<usize>,
    /// speed: also run the bus rows with the peers of another slipstream build, side by side
    /// with this one's, e.g. --with-build uring=/tmp/uring/release/slipstream (built with
    /// `cargo build --release --features uring`); repeatable
    #[arg(long, value_name = "LABEL=PATH")]
    pub with_build: Vec<String>,
    /// fleet: how many vehicles, in turn
    #[arg(long, value_delimiter = ',', default_value = "1,2,4,8")]
    pub fleet_vehicles: Vec<usize>,
    /// fleet: the links' caps in Mbit/s, in turn
    #[arg(long, value_delimiter = ',', default_value = "1000,100")]
    pub fleet_caps: Vec<u32>,
    /// fleet: seconds each batch of vehicles drives (realtime)
    #[arg(long, default_value_t = 20.0)]
    pub fleet_seconds: f64,
    /// fleet: what the client PC reads (its camera.read): a link copy (lz4, jpeg, png, raw)
    /// or "published"
    #[arg(long, default_value = "jpeg", value_parser = ["published", "raw", "lz4", "jpeg", "png"])]
    pub fleet_frames: String,
    /// fleet: 1 router, or a mesh of 3 (a subnet each, a backbone between them; vehicle i's
    /// simulator on subnet i % 3, its detector and ACC on the next)
    #[arg(long, default_value_t = 1, value_parser = clap::builder::TypedValueParser::map(
        clap::builder::PossibleValuesParser::new(["1", "3"]),
        |v: String| v.parse::<usize>().unwrap_or(1)
    ))]
    pub fleet_routers: usize,
    /// fleet: a Zenoh setting for every node and the router, e.g. --fleet-cfg
    /// transport/link/tx/queue/size/real_time:16 (KEY:VALUE as --cfg; repeatable)
    #[arg(long, value_name = "KEY:VALUE")]
    pub fleet_cfg: Vec<String>,
    /// Also draw how the cost grows (scale, fanout, router: whichever ran) into this PNG
    #[arg(long, value_name = "FILE")]
    pub plot: Option<std::path::PathBuf>,
}

/// Runs the suites; progress goes to stderr.
pub fn run(args: &BenchArgs) -> Result<BenchReport> {
    if cfg!(debug_assertions) {
        eprintln!("warning: this is a debug build; figures mean little. Use `cargo run --release -- bench`.");
    }
    let suites = if args.suites.is_empty() {
        vec![Suite::Speed, Suite::Frames, Suite::Contention, Suite::Sim, Suite::Fanout, Suite::Router]
    } else {
        args.suites.clone()
    };
    let repeat = if args.quick { 1 } else { args.repeat.max(1) };
    let builds = cases::other_builds(&args.with_build)?;
    let seed = python_available();
    let all = cases::cases(&suites, args.quick, &builds, seed);
    if !seed && !all.is_empty() {
        eprintln!("note: no {PYTHON} here: the seed's Python rows are left out");
    }
    let result = run_cases(&all, repeat);
    remove_seed_script();
    let rows = result?;
    let ratios = ratios::ratios(&rows, &builds);
    let sim = if suites.contains(&Suite::Sim) { sim::run(args.quick, repeat)? } else { Vec::new() };
    let scale = match suites.contains(&Suite::Scale) {
        true => run_scale(args)?,
        false => Vec::new(),
    };
    let counts = |asked: &[usize], what: &str, max: usize| -> Result<Vec<usize>> {
        anyhow::ensure!(
            !asked.is_empty() && asked.iter().all(|n| (1..=max).contains(n)),
            "--{what}: give 1 to {max} per run, e.g. --{what} 1,2,4,8"
        );
        Ok(if args.quick { vec![1, 2] } else { asked.to_vec() })
    };
    let fanout = match suites.contains(&Suite::Fanout) {
        true => growth::fanout(&counts(&args.subscribers, "subscribers", 32)?, args.quick, repeat)?,
        false => Vec::new(),
    };
    let router = match suites.contains(&Suite::Router) {
        true => growth::router(&counts(&args.vehicles, "vehicles", 64)?, args.quick, repeat)?,
        false => Vec::new(),
    };
    let fleet = match suites.contains(&Suite::Fleet) {
        true => run_fleet(args)?,
        false => Vec::new(),
    };
    let nodes = match suites.contains(&Suite::Nodes) {
        true => nodes::run(args.quick, repeat)?,
        false => Vec::new(),
    };
    let command = std::env::args().collect::<Vec<_>>().join(" ");
    let report = BenchReport { command, rows, ratios, sim, scale, fanout, router, fleet, nodes };
    if let Some(path) = &args.plot {
        plot::growth(&report, path)?;
        eprintln!("plot: {}", path.display());
    }
    Ok(report)
}

/// Each point-to-point case `repeat` times, a progress line per run; a row per case.
fn run_cases(all: &[cases::Case], repeat: usize) -> Result<Vec<Row>> {
    let total = all.len() * repeat;
    let mut done = 0;
    let mut rows = Vec::new();
    for case in all {
        let (table, path) = (case.id.table.label(), case.id.path.label());
        let mut runs = Vec::new();
        for _ in 0..repeat {
            done += 1;
            eprint!("[{done}/{total}] {table} / {path} ... ");
            let (s, r) = run_case(&case.spec).with_context(|| format!("{table} / {path}"))?;
            let f = figures::figures(&case.spec, &s, &r);
            eprintln!(
                "{} sent, {} received{}",
                s.sent,
                r.received,
                f.p50.map(|p| format!(", p50 {p:.0} us")).unwrap_or_default()
            );
            runs.push(f);
        }
        rows.push(figures::row(case, &runs));
    }
    Ok(rows)
}

fn run_scale(args: &BenchArgs) -> Result<Vec<scale::ScaleRow>> {
    if args.quick {
        return scale::run(&[1, 2], 3.0);
    }
    anyhow::ensure!(
        !args.loops.is_empty() && args.loops.iter().all(|n| (1..=32).contains(n)),
        "--loops: give 1 to 32 loops per batch, e.g. --loops 1,2,4,8"
    );
    anyhow::ensure!(args.scale_seconds >= 1.0, "--scale-seconds must be at least 1");
    scale::run(&args.loops, args.scale_seconds)
}

fn run_fleet(args: &BenchArgs) -> Result<Vec<fleet::FleetRow>> {
    anyhow::ensure!(args.fleet_seconds >= 5.0, "--fleet-seconds must be at least 5");
    anyhow::ensure!(
        !args.fleet_vehicles.is_empty() && args.fleet_vehicles.iter().all(|n| (1..=64).contains(n)),
        "--fleet-vehicles: give 1 to 64 per run, e.g. --fleet-vehicles 1,2,4,8"
    );
    let plan = fleet::FleetPlan {
        vehicles: args.fleet_vehicles.clone(),
        caps_mbit_s: args.fleet_caps.clone(),
        seconds: if args.quick { 5.0 } else { args.fleet_seconds },
        frames: args.fleet_frames.clone(),
        cfg: args.fleet_cfg.clone(),
        routers: args.fleet_routers,
    };
    anyhow::ensure!(
        plan.caps_mbit_s.iter().all(|c| (1..=100_000).contains(c)),
        "--fleet-caps: give link speeds in Mbit/s, e.g. --fleet-caps 1000,100"
    );
    fleet::run(&plan)
}
