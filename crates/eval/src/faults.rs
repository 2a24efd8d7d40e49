//! `slipstream eval faults`: the ACC's safety envelope under injected network faults.
//!
//! For each scenario, a fault-free run first (the baseline), then one axis at a time, in
//! rising steps: perception delay, perception loss (independent), perception loss (bursty,
//! Gilbert-Elliott) and control-command loss. Each run goes through the same path as
//! `eval acc` ([`super::acc::run_one`]: the nodes as processes in lockstep, the faults
//! injected by `--faults` where samples enter the ACC or the simulator) and is judged against
//! the baseline: a run holds when it has no collision the baseline does not have, no more
//! emergency braking than the baseline needs (plus [`EMERGENCY_SLACK_S`]), and every comfort
//! aim the baseline meets. An axis stops at its first failure; the envelope is the largest
//! value that held before it.

use std::path::{Path, PathBuf};
use std::time::Instant;

use crate::error::{Error, Result};
use crate::plot::Drawn;
use serde::Serialize;

use super::acc::{run_one, EvalAccArgs, ScenarioResult, Under};
use super::Metrics;
use slipstream_acc::PerceptionSource;
use slipstream_contract::config::{FaultArgs, FaultProfile, GilbertElliott, Loss, TopicFaults};
use slipstream_contract::topics::{self, Topic};
use slipstream_launch::OwnNodes;
use slipstream_sim::Scenario;

/// More emergency braking than the fault-free run, by this many simulated seconds, fails a run.
pub(crate) const EMERGENCY_SLACK_S: f64 = 0.3;

/// The scenarios the envelope is taken over by default: every built-in one with a vehicle to
/// follow (open road has nobody ahead; busy traffic's lead changes at random).
pub(crate) const STANDARD: &[&str] = &[
    "steady-follow",
    "approach-slower-lead",
    "lead-brakes-to-stop",
    "stop-and-go",
    "cut-in",
    "cut-out-revealing-stopped-car",
    "curve-follow",
];

#[derive(Debug, Clone, clap::Args)]
pub struct EvalFaultsArgs {
    /// Scenarios (built-in names or .json5 files) [default: every built-in scenario with a
    /// vehicle to follow]
    #[arg(long = "scenario", value_name = "NAME")]
    pub scenarios: Vec<String>,
    /// Where the ACC's vehicles ahead come from (faults go on perception/objects with the
    /// camera, on objects with ground truth)
    #[arg(long, value_enum, default_value = "camera")]
    pub perception: PerceptionSource,
    /// Perception delays to try, ms of simulated time, rising
    #[arg(long, value_delimiter = ',', default_values_t = [50.0, 100.0, 200.0, 300.0, 500.0])]
    pub delays_ms: Vec<f64>,
    /// Perception losses to try (independent, then bursty), fractions, rising
    #[arg(long, value_delimiter = ',', default_values_t = [0.1, 0.2, 0.3, 0.5])]
    pub losses: Vec<f64>,
    /// Mean burst length of the bursty perception loss, in messages
    #[arg(long, default_value_t = 5.0)]
    pub burst_len: f64,
    /// Control-command losses to try (at the simulator), fractions, rising
    #[arg(long, value_delimiter = ',', default_values_t = [0.1, 0.2, 0.5])]
    pub control_losses: Vec<f64>,
    /// Seed of the injected faults (the same seed drops the same messages)
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// End each run after this many simulated seconds instead of the scenario's own duration
    #[arg(long)]
    pub duration: Option<f64>,
    /// Wall-clock limit per run, seconds
    #[arg(long, default_value_t = 600.0)]
    pub timeout: f64,
    /// Draw the envelope into this PNG
    #[arg(long, value_name = "FILE.png")]
    pub plot: Option<PathBuf>,
    /// Print JSON instead of the table
    #[arg(long)]
    pub json: bool,
    /// Keep the nodes' logs here, one directory per run [default: a temporary directory,
    /// removed at the end]
    #[arg(long, value_name = "DIR")]
    pub logs: Option<PathBuf>,
    /// Nodes of your own in the place of ours. Faults are injected by our nodes as they
    /// receive: with your detector every axis runs (perception faults at slipstream-acc); with
    /// your controller only control loss (at the simulator), the perception axes are marked
    /// not injected
    #[command(flatten)]
    pub own: slipstream_launch::OwnNodeArgs,
}

/// One direction of the sweep.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Axis {
    PerceptionDelay,
    PerceptionLoss,
    PerceptionBurstyLoss,
    ControlLoss,
}

impl Axis {
    pub const ALL: [Axis; 4] =
        [Axis::PerceptionDelay, Axis::PerceptionLoss, Axis::PerceptionBurstyLoss, Axis::ControlLoss];

    pub fn title(self, burst_len: f64) -> String {
        match self {
            Axis::PerceptionDelay => "perception delay (ms)".into(),
            Axis::PerceptionLoss => "perception loss".into(),
            Axis::PerceptionBurstyLoss => format!("perception loss, bursts of {burst_len}"),
            Axis::ControlLoss => "control loss".into(),
        }
    }

    fn values(self, args: &EvalFaultsArgs) -> &[f64] {
        match self {
            Axis::PerceptionDelay => &args.delays_ms,
            Axis::PerceptionLoss | Axis::PerceptionBurstyLoss => &args.losses,
            Axis::ControlLoss => &args.control_losses,
        }
    }

    /// The value as the table shows it.
    fn show(self, v: f64) -> String {
        match self {
            Axis::PerceptionDelay => format!("{v:.0} ms"),
            _ => format!("{:.0} %", v * 100.0),
        }
    }

    /// The profile of one run: `value` on this axis, nothing else.
    fn profile(self, value: f64, args: &EvalFaultsArgs) -> FaultProfile {
        let perception: Topic = match args.perception {
            PerceptionSource::Camera => topics::PERCEPTION_OBJECTS.topic,
            PerceptionSource::GroundTruth => topics::OBJECTS.topic,
        };
        let none = TopicFaults::default();
        let (topic, node, faults) = match self {
            Axis::PerceptionDelay => (perception, "acc", TopicFaults { delay_ms: value, ..none }),
            Axis::PerceptionLoss => (perception, "acc", TopicFaults { loss: Some(Loss::Independent(value)), ..none }),
            Axis::PerceptionBurstyLoss => (
                perception,
                "acc",
                TopicFaults { loss: Some(Loss::Bursty(GilbertElliott::with_mean(value, args.burst_len))), ..none },
            ),
            Axis::ControlLoss => {
                (topics::VEHICLE_CONTROL.topic, "sim", TopicFaults { loss: Some(Loss::Independent(value)), ..none })
            }
        };
        let name = format!("{:?} {}", self, self.show(value)).to_lowercase();
        FaultProfile::single(&name, args.seed, topic, TopicFaults { at: vec![node.into()], ..faults })
    }
}

/// The figures of one run that the envelope is judged by.
#[derive(Debug, Clone, Serialize)]
pub struct RunFigures {
    pub collisions: u64,
    pub emergency_s: f64,
    pub min_gap_m: Option<f64>,
    pub max_decel_mps2: f64,
    pub max_jerk_mps3: f64,
    pub wall_time_s: f64,
}

impl RunFigures {
    fn of(r: &ScenarioResult) -> RunFigures {
        let m = &r.metrics;
        RunFigures {
            collisions: m.collisions,
            emergency_s: m.emergency_s,
            min_gap_m: m.min_gap_m,
            max_decel_mps2: m.max_decel_mps2,
            max_jerk_mps3: m.max_jerk_mps3,
            wall_time_s: r.wall_time_s,
        }
    }
}

/// One faulted run.
#[derive(Debug, Clone, Serialize)]
pub struct Trial {
    pub value: f64,
    /// Why it did not hold; None: it held.
    pub failure: Option<String>,
    pub figures: RunFigures,
}

#[derive(Debug, Clone, Serialize)]
pub struct AxisResult {
    pub axis: Axis,
    pub trials: Vec<Trial>,
    /// The largest value that held before the first failure (0: the first value tried failed).
    pub envelope: f64,
    /// Every value tried held: the envelope is at least `envelope`.
    pub held_throughout: bool,
    /// Why the axis was not tried: its faults would land in a node of the user's own.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub not_injected: Option<String>,
}

#[derive(Debug, Clone, Serialize)]
pub struct ScenarioEnvelope {
    pub scenario: String,
    pub baseline: RunFigures,
    /// Aims the fault-free run already misses (not held against the faulted runs).
    pub baseline_misses: Vec<String>,
    pub axes: Vec<AxisResult>,
}

#[derive(Debug, Clone, Serialize)]
pub struct FaultsReport {
    pub command: String,
    pub perception: PerceptionSource,
    pub seed: u64,
    pub burst_len: f64,
    pub scenarios: Vec<ScenarioEnvelope>,
    pub plot: Option<PathBuf>,
    /// The nodes of the user's own it judged (their command and files by content); empty: ours.
    pub own: OwnNodes,
}

/// Why `run` does not hold against `baseline`; None when it holds.
pub fn judge(baseline: &Metrics, run: &Metrics, lockstep_timeouts: u64) -> Option<String> {
    if lockstep_timeouts > 0 {
        return Some(format!("{lockstep_timeouts} lockstep timeouts"));
    }
    if run.collisions > baseline.collisions {
        return Some(format!("{} collision(s)", run.collisions));
    }
    if run.emergency_s > baseline.emergency_s + EMERGENCY_SLACK_S {
        return Some(format!("emergency braking {:.1} s (fault-free {:.1} s)", run.emergency_s, baseline.emergency_s));
    }
    let comfort = |m: &Metrics| -> Vec<(String, bool, Option<f64>)> {
        m.checks.iter().filter(|c| c.name.starts_with("max ")).map(|c| (c.name.clone(), c.pass, c.value)).collect()
    };
    for ((name, base_pass, _), (_, pass, value)) in comfort(baseline).into_iter().zip(comfort(run)) {
        if base_pass && !pass {
            let short = name.replace(" outside emergencies", "");
            return Some(format!("{short} {}", super::fmt_opt(value, 2)));
        }
    }
    None
}

/// The sweep's flags, checked before any run starts: every value of every axis rises and makes
/// a valid fault profile.
fn check_args(args: &EvalFaultsArgs) -> Result<()> {
    if args.timeout <= 0.0 || args.timeout.is_nan() {
        return Err(Error::flag("--timeout", "must be > 0"));
    }
    if args.burst_len < 1.0 || args.burst_len.is_nan() {
        return Err(Error::flag("--burst-len", "must be >= 1 (messages)"));
    }
    for axis in Axis::ALL {
        let v = axis.values(args);
        let title = axis.title(args.burst_len);
        if !v.windows(2).all(|w| w[0] < w[1]) {
            return Err(Error::flag(format!("the values of {title}"), format!("must rise: {v:?}")));
        }
        // Every value makes a valid profile (probabilities in range, delays >= 0).
        for &x in v {
            FaultProfile::parse(&axis.profile(x, args).to_json5(), "--losses/--delays-ms", "check")
                .map_err(|e| Error::flag(format!("{title} = {x}"), format!("makes no valid fault profile: {e}")))?;
        }
    }
    Ok(())
}

pub fn run(args: &EvalFaultsArgs, connect: &slipstream_contract::config::ConnectArgs) -> Result<FaultsReport> {
    connect.topic_map()?;
    check_args(args)?;
    let names: Vec<String> = if args.scenarios.is_empty() {
        STANDARD.iter().map(|s| s.to_string()).collect()
    } else {
        args.scenarios.clone()
    };
    let scenarios: Vec<Scenario> = names
        .iter()
        .map(|n| Scenario::find(n).and_then(|s| s.one_ego("slipstream eval faults")))
        .collect::<Result<_, _>>()?;
    let logs = match &args.logs {
        Some(dir) => dir.clone(),
        None => std::env::temp_dir().join(format!("slipstream-eval-faults-{}", std::process::id())),
    };
    let acc_args = EvalAccArgs {
        scenarios: Vec::new(),
        perception: args.perception,
        plots: None,
        json: false,
        duration: args.duration,
        timeout: args.timeout,
        logs: None,
        jobs: Some(1),
        link: Default::default(),
        faults: FaultArgs::default(),
        own: Default::default(),
    };
    let own = args.own.nodes_started_here()?;
    let rt = tokio::runtime::Runtime::new().map_err(Error::system("start the async runtime"))?;
    // Which axes cannot be tried with the user's nodes: the same for every scenario.
    let skipped = Axis::ALL.map(|a| not_injected(a, args, &own));
    let tried = Axis::ALL.iter().zip(&skipped).filter(|(_, why)| why.is_none());
    let total_runs: usize = names.len() * (1 + tried.map(|(a, _)| a.values(args).len()).sum::<usize>());
    let mut done_runs = 0usize;
    let started = Instant::now();
    let mut out = Vec::new();
    for (arg, scenario) in names.iter().zip(scenarios) {
        let name = scenario.name.clone();
        let mut one = |label: &str, faults: Option<FaultProfile>| -> Result<ScenarioResult> {
            done_runs += 1;
            eprint!("[{done_runs}/<={total_runs}, {:.0} s] {name}: {label} ... ", started.elapsed().as_secs_f64());
            let dir = logs.join(&name).join(label.replace([' ', '%', '/'], "_"));
            let under = Under { faults, own: own.clone() };
            rt.block_on(run_one(arg, scenario.clone(), &acc_args, under, None, &dir)).map_err(|e| Error::Run {
                run: format!("{name}, {label}"),
                logs: dir.clone(),
                source: Box::new(e),
            })
        };
        let base = one("fault-free", None)?;
        eprintln!(
            "{} collisions, emergency {:.1} s, max jerk {:.2}",
            base.metrics.collisions, base.metrics.emergency_s, base.metrics.max_jerk_mps3
        );
        let baseline_misses: Vec<String> =
            base.metrics.checks.iter().filter(|c| !c.pass).map(|c| c.name.clone()).collect();
        let axes = Axis::ALL
            .iter()
            .zip(&skipped)
            .map(|(a, why)| try_axis(*a, args, why.clone(), &base.metrics, &mut one))
            .collect::<Result<_>>()?;
        out.push(ScenarioEnvelope { scenario: name, baseline: RunFigures::of(&base), baseline_misses, axes });
    }
    if args.logs.is_none() {
        let _ = std::fs::remove_dir_all(&logs);
    }
    let mut report = FaultsReport {
        command: std::env::args().collect::<Vec<_>>().join(" "),
        perception: args.perception,
        seed: args.seed,
        burst_len: args.burst_len,
        scenarios: out,
        plot: None,
        own,
    };
    if let Some(path) = &args.plot {
        plot(&report, path)?;
        report.plot = Some(path.clone());
    }
    Ok(report)
}

/// One axis of one scenario: its values, rising, until the first that fails, each judged
/// against the fault-free run's `base`; marked and not run when `skipped` says why (its
/// faults would land in a node of the user's own).
fn try_axis(
    axis: Axis,
    args: &EvalFaultsArgs,
    skipped: Option<String>,
    base: &Metrics,
    one: &mut impl FnMut(&str, Option<FaultProfile>) -> Result<ScenarioResult>,
) -> Result<AxisResult> {
    if let Some(why) = skipped {
        eprintln!("{}: not injected ({why})", axis.title(args.burst_len));
        let not_injected = Some(why);
        return Ok(AxisResult { axis, trials: Vec::new(), envelope: 0.0, held_throughout: false, not_injected });
    }
    let mut trials = Vec::new();
    let mut envelope = 0.0;
    for &value in axis.values(args) {
        let label = format!("{} {}", axis.title(args.burst_len), axis.show(value));
        let r = one(&label, Some(axis.profile(value, args)))?;
        let failure = judge(base, &r.metrics, r.lockstep_timeouts);
        eprintln!("{}", failure.as_deref().unwrap_or("holds"));
        let failed = failure.is_some();
        trials.push(Trial { value, failure, figures: RunFigures::of(&r) });
        if failed {
            return Ok(AxisResult { axis, trials, envelope, held_throughout: false, not_injected: None });
        }
        envelope = value;
    }
    Ok(AxisResult { axis, trials, envelope, held_throughout: true, not_injected: None })
}

/// Why `axis` cannot be tried with the user's nodes `own`: the node its faults would land in.
fn not_injected(axis: Axis, args: &EvalFaultsArgs, own: &OwnNodes) -> Option<String> {
    let value = axis.values(args).first().copied()?;
    let profile = axis.profile(value, args);
    own.fault_into_foreign(&profile).map(|(topic, node)| format!("{topic} at your {}", node.role.process()))
}

/// One cell of the table: "300 ms (500 ms: collision)", ">= 500 ms", "< 50 ms (50 ms: ...)".
fn cell(a: &AxisResult) -> String {
    if let Some(why) = &a.not_injected {
        return format!("not injected ({why})");
    }
    let first_value = a.trials.first().map_or(0.0, |t| t.value);
    let failure = a.trials.iter().find(|t| t.failure.is_some());
    match failure {
        None => format!(">= {}", a.axis.show(a.envelope)),
        Some(t) => {
            let why = t.failure.as_deref().unwrap_or("");
            if a.envelope == 0.0 {
                format!("< {} ({}: {why})", a.axis.show(first_value), a.axis.show(t.value))
            } else {
                format!("{} ({}: {why})", a.axis.show(a.envelope), a.axis.show(t.value))
            }
        }
    }
}

/// The envelope as a markdown table.
pub fn markdown(r: &FaultsReport) -> String {
    let mut out = format!(
        "Safety envelope with {}, {} perception, seed {}: per axis the largest fault that held (no collision, no emergency braking beyond the fault-free run's + {EMERGENCY_SLACK_S} s, every comfort aim the fault-free run meets), and what failed first.\n\n",
        r.own.described("slipstream-acc"),
        r.perception.name(),
        r.seed
    );
    out.push_str("| scenario | fault-free | ");
    out.push_str(&Axis::ALL.iter().map(|a| a.title(r.burst_len)).collect::<Vec<_>>().join(" | "));
    out.push_str(" |\n|---|---|---|---|---|---|\n");
    for s in &r.scenarios {
        let b = &s.baseline;
        let base = format!(
            "{} coll., emerg. {:.1} s, jerk {:.1}{}",
            b.collisions,
            b.emergency_s,
            b.max_jerk_mps3,
            if s.baseline_misses.is_empty() { String::new() } else { " (misses an aim)".into() }
        );
        let cells: Vec<String> = s.axes.iter().map(cell).collect();
        out.push_str(&format!("| {} | {base} | {} |\n", s.scenario, cells.join(" | ")));
    }
    if let Some(p) = &r.plot {
        out.push_str(&format!("\nplot: {}\n", p.display()));
    }
    out
}

/// One panel per axis, a bar per scenario: the envelope (green: held at every value tried, so
/// at least this; orange: the limit found) and, in red, the first value that failed.
pub fn plot(r: &FaultsReport, path: &Path) -> Result<()> {
    use plotters::prelude::*;
    let (w, h) = (1200u32, 1000u32);
    super::plot::png(path, (w, h), |root| -> Drawn {
        let title = format!(
            "ACC safety envelope under injected faults ({} perception, seed {}): bars held (green: at every value tried), red x: first failure",
            r.perception.name(),
            r.seed
        );
        let root = root.titled(&title, ("sans-serif", 17))?;
        let panels = root.split_evenly((2, 2));
        let n = r.scenarios.len().max(1) as i32;
        let names: Vec<String> = r.scenarios.iter().map(|s| s.scenario.clone()).collect();
        for (i, axis) in Axis::ALL.iter().enumerate() {
            let scale = if *axis == Axis::PerceptionDelay { 1.0 } else { 100.0 };
            let top = r
                .scenarios
                .iter()
                .flat_map(|s| s.axes.iter().filter(|a| a.axis == *axis).flat_map(|a| a.trials.iter().map(|t| t.value)))
                .fold(0.0f64, f64::max)
                * scale
                * 1.15;
            let mut chart = ChartBuilder::on(&panels[i])
                .caption(axis.title(r.burst_len), ("sans-serif", 18))
                .margin(10)
                .x_label_area_size(40)
                .y_label_area_size(230)
                .build_cartesian_2d(0.0..top.max(1.0), (0..n).into_segmented())?;
            chart
                .configure_mesh()
                .disable_y_mesh()
                .y_labels(n as usize)
                .y_label_formatter(&|y| match y {
                    SegmentValue::CenterOf(i) => names.get(*i as usize).cloned().unwrap_or_default(),
                    _ => String::new(),
                })
                .x_desc(if *axis == Axis::PerceptionDelay { "held up to (ms)" } else { "held up to (%)" })
                .label_style(("sans-serif", 13))
                .draw()?;
            for (j, s) in r.scenarios.iter().enumerate() {
                let Some(a) = s.axes.iter().find(|a| a.axis == *axis) else { continue };
                let color = if a.held_throughout { RGBColor(44, 160, 44) } else { RGBColor(255, 127, 14) };
                let row = SegmentValue::CenterOf(j as i32);
                if a.envelope > 0.0 {
                    chart.draw_series(std::iter::once(PathElement::new(
                        vec![(0.0, row.clone()), (a.envelope * scale, row.clone())],
                        color.stroke_width(18),
                    )))?;
                }
                if let Some(t) = a.trials.iter().find(|t| t.failure.is_some()) {
                    chart.draw_series(std::iter::once(Cross::new(
                        (t.value * scale, row),
                        8,
                        RGBColor(214, 39, 40).stroke_width(4),
                    )))?;
                }
            }
        }
        Ok(())
    })
}
