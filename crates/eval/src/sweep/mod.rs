//! `slipstream eval sweep`: driving judged at scale. It generates N scenarios from
//! parameterised families ([`families`]), each declaring what its own physics warrants
//! ([`warrant`]), runs each through the same lockstep loop as `eval acc`
//! ([`crate::acc::run_all`]), and reports rates per 1,000 km per family ([`rates`]), not
//! anecdotes, with the worst runs named and their scenario files kept for `eval acc
//! --scenario FILE`. [`shard`] splits a sweep across machines and merges it again; [`compare`]
//! sets two sweeps of the same scenarios side by side.

pub mod compare;
pub mod families;
pub mod plot;
pub mod rates;
pub mod shard;
pub(crate) mod warrant;

use std::path::{Path, PathBuf};
use std::time::Instant;

use crate::error::{Error, Result};
use serde::Serialize;

use super::acc::{jobs, run_all, EvalAccArgs};
use families::{nth, Family};
use rates::{faults_of, worst, Rates, SweepRun};
use shard::Shard;
use slipstream_acc::PerceptionSource;
use slipstream_contract::config::FaultArgs;
use slipstream_launch::{LinkKind, OwnNodeArgs, OwnNodes};
use slipstream_sim::Scenario;

#[derive(Debug, Clone, clap::Args)]
pub struct EvalSweepArgs {
    /// Scenarios to generate and run, spread evenly over the families
    #[arg(long, default_value_t = 1000)]
    pub count: usize,
    /// Seeds the generator: the same seed and count give the same scenarios
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Families to draw from (comma-separated) [default: all]
    #[arg(long, value_enum, value_delimiter = ',')]
    pub families: Vec<Family>,
    /// Runs at once, each loop in its own processes, ports and namespace (lockstep runs are
    /// the same whatever runs beside them) [default: the CPU cores, at most 4]
    #[arg(long, short = 'j', value_name = "N")]
    pub jobs: Option<usize>,
    /// Where the ACC's vehicles ahead come from: camera (slipstream-detect on the rendered
    /// frames) or ground-truth (the simulator's objects)
    #[arg(long, value_enum, default_value = "camera")]
    pub perception: PerceptionSource,
    /// Where the scenarios (scenarios/<name>.json5), the report (sweep.json), the plot
    /// (rates.png) and the logs of the runs that missed an aim (logs/) go
    #[arg(long = "report", alias = "out", value_name = "DIR", default_value = "reports/sweep")]
    pub out: PathBuf,
    /// The worst runs named in the report
    #[arg(long, default_value_t = 10, value_name = "N")]
    pub worst: usize,
    /// Print JSON instead of the table
    #[arg(long)]
    pub json: bool,
    /// Wall-clock limit per run, seconds
    #[arg(long, default_value_t = 300.0)]
    pub timeout: f64,
    /// Run only the K-th of N shares of the sweep (the runs whose index i has i % N == K - 1),
    /// e.g. one per machine of a CI matrix with the same --seed and --count; `slipstream eval
    /// sweep-merge` joins the shards' reports into the whole sweep's
    #[arg(long, value_name = "K/N")]
    pub shard: Option<Shard>,
    /// Keep every run's node logs under --report/logs, not only those of the runs that missed
    /// an aim (a thousand runs' logs take gigabytes)
    #[arg(long)]
    pub keep_logs: bool,
    #[command(flatten)]
    pub own: OwnNodeArgs,
}

#[derive(Debug, Clone, Serialize, serde::Deserialize)]
pub struct SweepReport {
    pub command: String,
    pub seed: u64,
    /// The whole sweep's --count (a shard runs its share of it).
    #[serde(default)]
    pub count: usize,
    /// --families as given (empty: all).
    #[serde(default)]
    pub asked_families: Vec<Family>,
    /// The share of the sweep this report holds; None for a whole sweep (or a merge).
    #[serde(default)]
    pub shard: Option<Shard>,
    pub perception: PerceptionSource,
    /// The nodes of the user's own it judged (their command and files by content); empty: ours.
    #[serde(default)]
    pub own: OwnNodes,
    pub jobs: usize,
    pub wall_s: f64,
    /// Over every run, then per family.
    pub all: Rates,
    pub families: Vec<Rates>,
    /// The worst runs, worst first (names; their files under `out/scenarios/`).
    pub worst: Vec<String>,
    pub runs: Vec<SweepRun>,
    pub plot: Option<PathBuf>,
    /// Whether every family meets the bar ([`Rates::meets_the_bar`]).
    pub pass: bool,
}

/// Generates the scenarios into `out/scenarios/` and returns them with their files; families
/// in turn, so every family has its share of any count.
fn write_scenarios(args: &EvalSweepArgs) -> Result<Vec<(SweepRun, Scenario)>> {
    let families: Vec<Family> = if args.families.is_empty() { Family::ALL.to_vec() } else { args.families.clone() };
    let dir = args.out.join("scenarios");
    std::fs::create_dir_all(&dir).map_err(Error::file("create (--report)", &dir))?;
    let mut out = Vec::with_capacity(args.count);
    for index in 0..args.count {
        if args.shard.is_some_and(|s| !s.takes(index)) {
            continue;
        }
        // Dealt in turn, each family's j-th the full sweep's: --families picks scenarios out
        // of the full sweep, it does not draw others.
        let g = nth(families[index % families.len()], args.seed, index / families.len());
        let file = dir.join(format!("{}.json5", g.name));
        let text = format!(
            "// Generated by `slipstream eval sweep --seed {}` (family {}).\n{}\n",
            args.seed,
            g.family.name(),
            serde_json::to_string_pretty(&g.scenario)
                .map_err(|e| Error::Bug(format!("a generated scenario does not serialize: {e}")))?
        );
        let scenario = Scenario::parse(&text, &file.display().to_string())
            .map_err(|e| Error::Bug(format!("the generator wrote an invalid scenario: {e}\n{text}")))?;
        std::fs::write(&file, &text).map_err(Error::file("write", &file))?;
        let run = SweepRun {
            index,
            name: g.name,
            family: g.family,
            description: scenario.description.clone(),
            file: file.display().to_string(),
            result: None,
            error: None,
        };
        out.push((run, scenario));
    }
    Ok(out)
}

/// Runs the sweep, telling `on_run` of each run as it finishes.
pub fn run(
    args: &EvalSweepArgs,
    connect: &slipstream_contract::config::ConnectArgs,
    mut on_run: impl FnMut(RunDone),
) -> Result<SweepReport> {
    connect.topic_map()?;
    if args.count == 0 {
        return Err(Error::flag("--count", "must be at least 1"));
    }
    if args.timeout <= 0.0 || args.timeout.is_nan() {
        return Err(Error::flag("--timeout", "must be > 0"));
    }
    let jobs = jobs(args.jobs)?;
    let own = args.own.nodes_started_here()?;
    let generated = write_scenarios(args)?;
    let logs = args.out.join("logs");
    let acc_args = EvalAccArgs {
        scenarios: Vec::new(),
        perception: args.perception,
        plots: None,
        json: false,
        duration: None,
        timeout: args.timeout,
        logs: Some(logs.clone()),
        jobs: Some(jobs),
        link: LinkKind::default(),
        faults: FaultArgs::default(),
        // Parsed once above, handed to every run with `under`.
        own: OwnNodeArgs::default(),
    };
    let (mut runs, scenarios): (Vec<SweepRun>, Vec<(String, Scenario)>) =
        generated.into_iter().map(|(run, s)| (run.clone(), (run.file, s))).unzip();
    let started = Instant::now();
    let total = runs.len();
    let under = super::acc::Under { faults: None, own: own.clone() };
    let results = run_all(scenarios, &acc_args, &under, connect.topics.clone(), &logs, jobs, |done, name, result| {
        on_run(RunDone { done, total, name, failed: judged(name, result, (&logs, args.keep_logs), args.perception) })
    })?;
    for (run, result) in runs.iter_mut().zip(results) {
        match result {
            Ok(r) => run.result = Some(r),
            Err(e) => run.error = Some(e.chain()),
        }
    }
    let wall_s = started.elapsed().as_secs_f64();
    let of = ReportOf {
        seed: args.seed,
        count: args.count,
        perception: args.perception,
        asked_families: args.families.clone(),
        shard: args.shard,
        own: own.clone(),
        out: &args.out,
        worst: args.worst,
    };
    Ok(report(&of, runs, jobs, wall_s))
}

/// What a report says besides its runs: the sweep it is of, where it goes, how many worst runs
/// it names.
pub(crate) struct ReportOf<'a> {
    pub(crate) seed: u64,
    pub(crate) count: usize,
    pub(crate) perception: PerceptionSource,
    pub(crate) asked_families: Vec<Family>,
    pub(crate) shard: Option<Shard>,
    pub(crate) own: OwnNodes,
    pub(crate) out: &'a Path,
    pub(crate) worst: usize,
}

/// A run has finished: how many of how many, and why it failed if it did.
pub struct RunDone<'a> {
    pub done: usize,
    pub total: usize,
    pub name: &'a str,
    /// None when the run passed; else the aims it missed or the error that stopped it.
    pub failed: Option<String>,
}

/// Why a run failed (None: it passed). A clean run's logs are removed unless `keep` (a
/// thousand runs' logs would fill the disk); the failures' are kept.
fn judged(
    name: &str,
    result: &Result<crate::acc::ScenarioResult>,
    (logs, keep): (&Path, bool),
    perception: PerceptionSource,
) -> Option<String> {
    match result {
        Ok(r) if r.passed() => {
            if !keep {
                let _ = std::fs::remove_dir_all(logs.join(format!("{name}-{}", perception.name())));
            }
            None
        }
        Ok(r) => {
            let failed: Vec<&str> = r.metrics.checks.iter().filter(|c| !c.pass).map(|c| c.name.as_str()).collect();
            Some(format!("FAIL: {}", failed.join(", ")))
        }
        Err(e) => Some(format!("ERROR: {}", e.chain())),
    }
}

/// The rates, the worst runs and the plot.
pub(crate) fn report(args: &ReportOf, runs: Vec<SweepRun>, jobs: usize, wall_s: f64) -> SweepReport {
    let all = Rates::of("all", runs.iter());
    let mut present: Vec<Family> = runs.iter().map(|r| r.family).collect();
    present.sort();
    present.dedup();
    let families: Vec<Rates> =
        present.iter().map(|f| Rates::of(f.name(), runs.iter().filter(|r| r.family == *f))).collect();
    let worst: Vec<String> = worst(&runs, args.worst).iter().map(|r| r.name.clone()).collect();
    let path = args.out.join("rates.png");
    let plot = match plot::rates(&families, &path) {
        Ok(()) => Some(path),
        Err(e) => {
            eprintln!("no plot: {e:#}");
            None
        }
    };
    let pass = all.meets_the_bar() && families.iter().all(Rates::meets_the_bar);
    SweepReport {
        command: std::env::args().collect::<Vec<_>>().join(" "),
        seed: args.seed,
        count: args.count,
        asked_families: args.asked_families.clone(),
        shard: args.shard,
        perception: args.perception,
        own: args.own.clone(),
        jobs,
        wall_s,
        all,
        families,
        worst,
        runs,
        plot,
        pass,
    }
}

/// The report as markdown: rates per family, then the worst runs with their files.
pub fn markdown(r: &SweepReport) -> String {
    let mut out = format!(
        "{} runs ({:?} perception, seed {}), {:.1} km in {:.0} s with {} at once.\n\n",
        r.all.runs, r.perception, r.seed, r.all.km, r.wall_s, r.jobs
    );
    out.push_str("| family | runs (passed, errors) | km | collisions | unwarranted emergencies | phantom-braking events | phantom braking s | per 1,000 km: collisions | unwarranted emergencies | phantom events | phantom s | comfort violations (runs) | time-gap RMS median s |\n");
    out.push_str("|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
    for f in r.families.iter().chain(std::iter::once(&r.all)) {
        let p = &f.per_1000_km;
        out.push_str(&format!(
            "| {} | {} ({}, {}) | {:.1} | {} | {} | {} | {:.1} | {:.1} | {:.1} | {:.1} | {:.1} | {} | {} |\n",
            f.family,
            f.runs,
            f.passed,
            f.errors,
            f.km,
            f.collisions,
            f.unwarranted_emergencies,
            f.phantom_braking_events,
            f.phantom_braking_s,
            p.collisions,
            p.unwarranted_emergencies,
            p.phantom_braking_events,
            p.phantom_braking_s,
            f.comfort_violations,
            super::fmt_opt(f.time_gap_rms_median_s, 3),
        ));
    }
    out.push_str(&format!(
        "\nBar: no collision, no unwarranted emergency, at most 1 phantom-braking event per 1,000 km, in every family: **{}**.\n",
        if r.pass { "met" } else { "not met" }
    ));
    if !r.worst.is_empty() {
        out.push_str("\nWorst runs (replay one with `slipstream eval acc --scenario FILE`):\n\n| run | what went wrong | scenario | file |\n|---|---|---|---|\n");
        for name in &r.worst {
            if let Some(run) = r.runs.iter().find(|x| &x.name == name) {
                out.push_str(&format!("| {} | {} | {} | {} |\n", run.name, faults_of(run), run.description, run.file));
            }
        }
    }
    out
}
