//! `slipstream eval`: scoring a node against the simulator's ground truth. The subcommands'
//! command lines and what each prints and exits with; the scoring itself is the eval layer's
//! ([`crate::eval`]).

use std::process::ExitCode;

use anyhow::{Context, Result};

use crate::cli::print_report;
use crate::config::ConnectArgs;

#[derive(clap::Subcommand)]
pub enum EvalCommand {
    /// Vehicle detection: runs scenarios in process (world, camera, detector and tracker; the
    /// ego keeps its start speed and slows for the vehicle ahead), matches detections to the ground truth of the same frame, and reports
    /// precision, recall and distance/lateral errors by range, and the lateral error 80-200 m
    /// ahead by range and the bend it is seen through (--family bend-neighbours scores the
    /// bends of `eval sweep`)
    Detect(DetectArgs),
    /// Adaptive cruise control: runs slipstream-sim (lockstep, fast), slipstream-detect and
    /// slipstream-acc as separate processes over Zenoh through each scenario and reports
    /// collisions, minimum gap and TTC, time-gap and speed errors, and comfort (accel, decel,
    /// jerk outside emergencies) and what a driver feels (unwarranted emergencies, phantom
    /// braking, stopping for nothing, acceleration swings behind a steady lead) against the
    /// aims, with traffic collisions counted, and where the time went; exits with 1 when a
    /// scenario misses one. Runs one scenario per CPU core at once (-j). The nodes talk over
    /// unix sockets in a namespace of their own (the topic config, -t, is passed on;
    /// connection flags are not). Example:
    ///
    ///   slipstream eval acc --perception ground-truth --plots plots/
    #[command(verbatim_doc_comment)]
    Acc(crate::eval::acc::EvalAccArgs),
    /// The ACC's safety envelope under network faults: for each scenario a fault-free run,
    /// then perception delay, perception loss (independent, then bursty) and control-command
    /// loss in rising steps, injected where samples enter the ACC and the simulator
    /// (lockstep: the same seed gives the same run). Prints, per scenario and axis, the largest
    /// fault with no collision, no emergency braking the fault-free run does not need and
    /// comfort kept, and what failed first (docs/faults.md). Example:
    ///
    ///   slipstream eval faults --scenario cut-in --plot envelope.png
    #[command(verbatim_doc_comment)]
    Faults(crate::eval::faults::EvalFaultsArgs),
    /// A platoon's string stability: runs a platoon scenario (several egos behind a scripted
    /// leader) in lockstep at each time gap, started in that gap's equilibrium, with every
    /// ego's own slipstream-acc (and slipstream-detect with the camera) in its namespace, and
    /// prints per car the peak speed error and deceleration after the leader's disturbance and
    /// their ratios to the car ahead (string-stable when every speed ratio is at most 1), the
    /// smallest time gap measured stable and the analytic bound 2 x (delay + actuator lag).
    /// Writes platoon.json, platoon.png and the runs' logs under --report. Example:
    ///
    ///   slipstream eval platoon --scenario platoon-8-hard-brake --time-gaps 1.0,1.8
    #[command(verbatim_doc_comment)]
    Platoon(crate::eval::platoon::EvalPlatoonArgs),
    /// Driving judged at scale: generates --count scenarios (default 1,000) from parameterised
    /// families (Euro NCAP car-to-car rear, cut-ins, cut-outs, braking leads, the edge of
    /// range, bends with vehicles in the next lanes, lane ends, dense traffic), each declaring
    /// what its physics warrants, runs each like `eval acc` and reports collisions,
    /// unwarranted emergencies and phantom braking per 1,000 km by family, comfort violations
    /// and the time-gap error, with the worst runs named (their files replay with `eval acc
    /// --scenario FILE`). Writes the scenarios, sweep.json and rates.png under --report; exits
    /// with 1 when a family misses the bar (no collision, no unwarranted emergency, at most
    /// one phantom-braking event per 1,000 km). Example:
    ///
    ///   slipstream eval sweep --count 40 --seed 7 --report /tmp/sweep
    #[command(verbatim_doc_comment)]
    Sweep(crate::eval::sweep::EvalSweepArgs),
    /// Joins the reports of a sweep's shards (`eval sweep --shard K/N`, e.g. one per machine
    /// of a CI matrix) into the report of the whole sweep: its runs in order, its rates, its
    /// worst runs and its verdict; exit 1 when it misses the bar, as `eval sweep`
    ///
    ///   slipstream eval sweep --count 6 --perception ground-truth --shard 1/2 --report shard-1   (machine 1)
    ///
    ///   slipstream eval sweep --count 6 --perception ground-truth --shard 2/2 --report shard-2   (machine 2)
    ///
    ///   slipstream eval sweep-merge shard-1 shard-2 --report sweep
    #[command(verbatim_doc_comment)]
    SweepMerge(crate::eval::sweep::shard::MergeArgs),
    /// Two sweeps of the same scenarios (the same --seed, --count, --families and
    /// --perception) side by side, family by family: runs passed and the rates per 1,000 km
    /// as BASE -> OTHER, with the runs whose verdict changed named. Yours against
    /// slipstream-acc, or one build against the last:
    ///
    ///   slipstream eval sweep --count 4 --perception ground-truth --report ours
    ///
    ///   slipstream eval sweep --count 4 --perception ground-truth --loop clients/python/examples/own_loop.json5 --report mine
    ///
    ///   slipstream eval sweep-compare ours mine
    #[command(verbatim_doc_comment)]
    SweepCompare(crate::eval::sweep::compare::CompareArgs),
}

/// `eval detect`'s command line.
#[derive(clap::Args)]
pub struct DetectArgs {
    /// Scenarios to run (names or files) [default: the standard set]
    #[arg(long = "scenario", value_name = "NAME")]
    pub scenarios: Vec<String>,
    /// Simulated seconds per scenario at most (as `eval acc --duration`)
    #[arg(long = "duration", alias = "seconds", default_value_t = 30.0)]
    pub seconds: f64,
    /// Print JSON instead of the table
    #[arg(long)]
    pub json: bool,
    /// Simulator settings to measure with (the cameras: resolution, field of view, mount);
    /// only the keys it changes are needed [default: config/sim.json5 when present, else
    /// built-in]
    #[arg(long, value_name = "FILE", env = "SLIPSTREAM_SIM_CONFIG")]
    pub settings: Option<std::path::PathBuf>,
    /// Detector settings to measure (thresholds, tracker, camera fusion), as
    /// `slipstream-detect --settings` takes them [default: config/detect.json5 when present,
    /// else built-in]
    #[arg(long, value_name = "FILE", env = "SLIPSTREAM_DETECT_CONFIG")]
    pub detect_settings: Option<std::path::PathBuf>,
    /// Put every frame through this encoding and back before the detector sees it, as a
    /// link copy would (raw, lz4, jpeg, png), and report its size and encode/decode time
    #[arg(long, value_name = "ENCODING")]
    pub frames: Option<String>,
    /// JPEG quality for --frames jpeg, 1..100
    #[arg(long, default_value_t = 85, value_parser = clap::value_parser!(u8).range(1..=100))]
    pub jpeg_quality: u8,
    /// Also score --count scenarios of this `eval sweep` family (the sweep's own, with
    /// --seed), e.g. bend-neighbours for the lateral error far ahead in bends
    #[arg(long, value_enum)]
    pub family: Option<crate::eval::sweep::families::Family>,
    /// How many scenarios of --family
    #[arg(long, default_value_t = 20)]
    pub count: usize,
    /// The sweep seed the --family scenarios come from
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Your own detector in slipstream-detect's place: a command line (split as a shell
    /// would), started for each scenario and fed every frame over the bus, scored on the same
    /// frames and ground truth (docs/own-node.md), e.g. "python3 my_detector.py"
    #[arg(long, value_name = "CMD", conflicts_with_all = ["frames", "detect_settings"])]
    pub detector: Option<String>,
    /// A loop file (docs/own-node.md) whose detector is scored, with its environment,
    /// working directory, readiness and log; the file may name no other node (eval detect
    /// renders the frames itself and runs no controller)
    #[arg(long = "loop", value_name = "FILE", conflicts_with_all = ["frames", "detect_settings"])]
    pub loop_file: Option<std::path::PathBuf>,
}

/// `slipstream eval ...`: the report (or JSON); exit 1 (an error saying so) when `acc` or
/// `sweep` missed an aim.
pub fn command(command: &EvalCommand, connect: &ConnectArgs) -> Result<ExitCode> {
    match command {
        EvalCommand::Detect(args) => detect(args),
        EvalCommand::Acc(args) => {
            use crate::eval::acc;
            let report = acc::run(args, connect)?;
            print_report(args.json, &report, acc::markdown)?;
            let failed = report.results.iter().filter(|r| !r.passed()).count();
            let total = report.results.len() + report.unfinished.len();
            match (failed, report.unfinished.len()) {
                (0, 0) => Ok(ExitCode::SUCCESS),
                (f, 0) => anyhow::bail!("{f} of {total} scenarios missed an aim"),
                (f, u) => anyhow::bail!("{u} of {total} scenarios did not finish, {f} missed an aim"),
            }
        }
        EvalCommand::Sweep(args) => sweep(args, connect),
        EvalCommand::Platoon(args) => platoon(args),
        EvalCommand::SweepMerge(args) => sweep_merge(args),
        EvalCommand::SweepCompare(args) => {
            let compared = crate::eval::sweep::compare::compare(args)?;
            print_report(args.json, &compared, crate::eval::sweep::compare::markdown)?;
            Ok(ExitCode::SUCCESS)
        }
        EvalCommand::Faults(args) => {
            use crate::eval::faults;
            let report = faults::run(args, connect)?;
            print_report(args.json, &report, faults::markdown)?;
            Ok(ExitCode::SUCCESS)
        }
    }
}

/// `eval platoon`: every time gap's run, the report in its directory, the tables.
fn platoon(args: &crate::eval::platoon::EvalPlatoonArgs) -> Result<ExitCode> {
    use crate::eval::platoon;
    let stem = std::path::Path::new(&args.scenario).file_stem().and_then(|s| s.to_str()).unwrap_or("platoon");
    let dir = match &args.report {
        Some(d) => d.clone(),
        None => super::fresh_report_dir(&format!("platoon-{stem}"))?,
    };
    let rt = tokio::runtime::Runtime::new()?;
    let report = rt.block_on(platoon::measure(args, &dir))?;
    let json = dir.join("platoon.json");
    std::fs::write(&json, serde_json::to_string_pretty(&report)?)
        .with_context(|| format!("write {}", json.display()))?;
    platoon::plot(&report, &dir.join("platoon.png"))?;
    print_report(args.json, &report, platoon::markdown)?;
    eprintln!("report in {}", dir.display());
    Ok(ExitCode::SUCCESS)
}

/// `eval detect`: the frames' link encoding by name, then the report.
fn detect(args: &DetectArgs) -> Result<ExitCode> {
    use crate::eval::{detect, link_codec::LinkCodec};
    let scenarios = detect::scenarios(&args.scenarios, args.family, args.count, args.seed)?;
    let settings = crate::sim::SimSettings::load_or_default(args.settings.as_deref())?;
    let detector = crate::perception::DetectSettings::resolve(args.detect_settings.as_deref())?;
    let codec = match args.frames.as_deref() {
        None => None,
        Some(name) => {
            let Some(e) = crate::config::CameraEncoding::ALL.into_iter().find(|e| e.name() == name) else {
                anyhow::bail!("--frames {name}: not a frame encoding (use raw, lz4, jpeg or png)");
            };
            Some(LinkCodec::new(e, args.jpeg_quality))
        }
    };
    let own = crate::launch::OwnNodeArgs {
        detector: args.detector.clone(),
        loop_file: args.loop_file.clone(),
        ..Default::default()
    }
    .nodes_started_here()?;
    refuse_beyond_a_detector(&own)?;
    let report = detect::evaluate(scenarios, args.seconds, (&settings, &detector), codec, own.detector.as_ref())?;
    print_report(args.json, &report, detect::markdown)?;
    Ok(ExitCode::SUCCESS)
}

/// What a loop file may give `eval detect`: a detector of the user's own, nothing else (the
/// frames are rendered in process, no controller runs, slipstream-detect's settings come
/// with --detect-settings).
fn refuse_beyond_a_detector(own: &crate::launch::OwnNodes) -> Result<()> {
    let Some(file) = &own.loop_file else { return Ok(()) };
    let b = &own.builtin;
    let extra = [
        (own.controller.is_some() || b.controller.is_some(), "controller"),
        (!own.others.is_empty(), "others"),
        (b.simulator.is_some(), "simulator"),
        (b.detector.is_some(), "detector"),
    ];
    if let Some((_, key)) = extra.iter().find(|(given, _)| *given) {
        anyhow::bail!(
            "{}: key `{key}`: eval detect scores a detector of your own alone (it renders the frames itself and runs no controller; slipstream-detect's settings come with --detect-settings) (fix: give eval detect a loop file with only `detector: {{ command: ... }}`, or --detector CMD)",
            file.path.display()
        );
    }
    if own.detector.as_ref().is_some_and(|d| d.run.ready.sample.is_some()) {
        anyhow::bail!(
            "{}: key `detector.ready.sample`: eval detect sends the first frame once the detector's token is seen, so no sample can come before (fix: leave `ready.sample` out: the token is awaited)",
            file.path.display()
        );
    }
    if own.detector.is_none() {
        anyhow::bail!(
            "{}: no `detector` command: eval detect has nothing of yours to score (fix: add `detector: {{ command: ... }}`)",
            file.path.display()
        );
    }
    Ok(())
}

/// `eval sweep-merge`: the shards' reports as one, written and shown as `eval sweep`'s.
fn sweep_merge(args: &crate::eval::sweep::shard::MergeArgs) -> Result<ExitCode> {
    let report = crate::eval::sweep::shard::merge(args)?;
    written(&report, &args.out, args.json)
}

/// A sweep's report: sweep.json in `out`, the table (or JSON), and an error when a family
/// missed the bar.
fn written(report: &crate::eval::sweep::SweepReport, out: &std::path::Path, json: bool) -> Result<ExitCode> {
    let file = out.join("sweep.json");
    std::fs::write(&file, serde_json::to_string_pretty(report)?)
        .with_context(|| format!("write {}", file.display()))?;
    print_report(json, report, crate::eval::sweep::markdown)?;
    eprintln!(
        "report: {}; plot: {}",
        file.display(),
        report.plot.as_ref().map_or("none".into(), |p| p.display().to_string())
    );
    if !report.pass {
        anyhow::bail!("the sweep missed the bar (table above)");
    }
    Ok(ExitCode::SUCCESS)
}

/// `eval sweep`: sweep.json under --report, the table, and an error when a family missed the bar.
fn sweep(args: &crate::eval::sweep::EvalSweepArgs, connect: &ConnectArgs) -> Result<ExitCode> {
    use crate::eval::sweep;
    // On a terminal a bar with the time left and a line per failed run; in a log a line per run.
    let shown = super::status::Status::counted(0, false);
    let started = std::time::Instant::now();
    let report = sweep::run(args, connect, |r| {
        shown.set_total(r.total as u64);
        shown.step();
        if r.failed.is_some() || !shown.is_live() {
            let elapsed = started.elapsed().as_secs_f64();
            let left = elapsed / r.done as f64 * (r.total - r.done) as f64;
            let verdict = r.failed.as_deref().unwrap_or("pass");
            shown.note(&format!("[{}/{}, {elapsed:.0} s, ~{left:.0} s left] {}: {verdict}", r.done, r.total, r.name));
        }
    })?;
    shown.finish();
    written(&report, &args.out, args.json)
}
