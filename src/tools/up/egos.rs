//! `slipstream up` on a scenario with several controlled vehicles (`egos`, a platoon): one
//! simulator, and per ego its ACC (and its detector with camera perception) in the ego's
//! namespace, started by the launch layer ([`crate::launch::EgoNodes`]). The live view has a
//! line per ego; the report judges each ego on its own topics exactly as `up` judges one, and
//! says what happened between them: collisions between controlled vehicles, and each one's
//! smallest gap, which for a follower is the gap to the ego ahead (its lead in ground truth).

use std::path::Path;
use std::time::Instant;

use anyhow::{Context, Result};
use serde::Serialize;

use super::{loop_spec, watch_until_over, UpArgs, UpReport, Watch};
use crate::acc::PerceptionSource;
use crate::config::ConnectArgs;
use crate::eval::judge::judge_ego;
use crate::eval::{fmt_opt, plot, Metrics};
use crate::launch::{LoopRun, Network};
use crate::sim::{EgoRun, Scenario};

/// One controlled vehicle's run, judged on its own topics.
#[derive(Debug, Clone, Serialize)]
pub struct EgoReport {
    /// Its namespace under the run's.
    pub namespace: String,
    /// Its collisions (with traffic or another ego), as the simulator counted them.
    pub collisions: u64,
    /// What the simulator saw of its controller (lockstep timeouts, stale or rejected
    /// commands); None when the simulator wrote no report.
    pub control: Option<EgoRun>,
    pub metrics: Option<Metrics>,
    /// Frame (or state) published -> control applied, p99, ms.
    pub loop_p99_ms: Option<f64>,
    pub trace: std::path::PathBuf,
}

/// What `up` refuses with several egos, and what to do instead.
/// `topics`: the run's topic map, whose namespace the hints put the first car under (`-n
/// lab/car1` for a run under `lab`).
pub fn check_args(args: &UpArgs, scenario: &Scenario, topics: &crate::TopicMap) -> Result<()> {
    let n = scenario.egos().len();
    let refuse = |flag: &str, fix: &str| {
        anyhow::bail!("{flag}: {} has {n} controlled vehicles, and {flag} follows one (fix: {fix})", scenario.name)
    };
    let first = scenario.egos().first().and_then(|e| e.namespace.clone()).unwrap_or_else(|| "car1".into());
    let car = match topics.namespace() {
        "" => first,
        ns => format!("{ns}/{first}"),
    };
    if args.record {
        refuse("--record", &format!("record one car's topics beside the run: `slipstream -n {car} record`"))?;
    }
    if args.view {
        refuse("--view", &format!("watch one car beside the run: `slipstream -n {car} view`"))?;
    }
    if args.ros2 {
        refuse("--ros2", &format!("bridge one car beside the run: `slipstream -n {car} ros2`"))?;
    }
    if args.set_speed.is_some() {
        refuse("--set-speed", "set each car's speed in the scenario: `egos[k].set_speed_mps`")?;
    }
    Ok(())
}

/// The loop with every ego's nodes, to the end of the scenario (or Ctrl-C); the report.
pub async fn run_loop(args: &UpArgs, connect: &ConnectArgs, scenario: Scenario, dir: &Path) -> Result<UpReport> {
    let started = Instant::now();
    let spec = loop_spec(args, &scenario)?;
    let faults = spec.faults.as_ref().map(|p| p.summary());
    let network = Network::User { connect, sim_elsewhere: false };
    let mut lp = LoopRun::open(spec, network, &dir.join("logs"), "up").await.context("up")?;
    let camera = args.perception == PerceptionSource::Camera;
    let mut watches = Vec::new();
    for ego in &lp.spec().egos {
        watches.push((ego.namespace.clone(), Watch::start(&lp.bus().scoped(&ego.namespace)?, camera).await?));
    }
    eprintln!("{}", super::header(&scenario.name, args, &lp, dir));
    lp.start().await?;
    let sim_started = Instant::now();
    let name = lp.spec().scenario.clone();
    let lines = |alive: &[String]| view_lines(&watches, &name, args, scenario.duration_s, alive);
    let stopped_by = watch_until_over(&mut lp, &lines, args, None).await?;
    let sim_ran_s = sim_started.elapsed().as_secs_f64();
    super::say_who_died(&mut lp, stopped_by);
    let nodes = lp.stop().await;
    let sim = lp.sim_report().ok();
    let ended = stopped_by.map(|signal| format!("stopped ({signal})"));
    let fallback = ended.clone().unwrap_or_else(|| "stopped".into());
    let mut egos = Vec::new();
    let mut first = None;
    for (k, (ns, watch)) in watches.iter().enumerate() {
        let rec = watch.recorder.take();
        let judged = judge_ego(&rec, &scenario, k, sim.as_ref(), &fallback);
        let trace = dir.join(format!("trace-{ns}.csv"));
        judged.trace.write_csv(&trace)?;
        if judged.trace.samples.len() > 1 {
            let title =
                format!("{} {ns} ({} clock, {} perception)", scenario.name, args.mode.name(), args.perception.name());
            plot::plot(&judged.trace, &title, &dir.join(format!("{ns}.png")))?;
        }
        let latency = std::mem::take(&mut *watch.latency.lock());
        let loop_p99_ms = latency.stats(false)[crate::observe::latency::WHOLE_LOOP].p99_ms;
        let control = sim.as_ref().and_then(|s| s.egos.get(k).cloned());
        let collisions = judged.trace.collisions;
        egos.push(EgoReport {
            namespace: ns.clone(),
            collisions,
            control,
            metrics: judged.metrics,
            loop_p99_ms,
            trace,
        });
        if k == 0 {
            first = Some((judged.trace, latency, rec.statuses.last().map(|s| s.msg.time_gap_s)));
        }
    }
    let topics = watches.iter().flat_map(|(_, w)| w.keys.view().keys).collect();
    drop(watches);
    let (trace, latency, time_gap) = first.context("a scenario with several egos has a first one")?;
    let sim_time_s = trace.samples.last().map_or(0.0, |s| s.t_s);
    let sim_wall_time_s = sim.as_ref().map_or(sim_ran_s, |s| s.wall_time_s);
    let lag_s = crate::vehicle::VehicleParams::of_class(scenario.ego().class.into()).actuator_lag_s;
    let report = UpReport {
        command: std::env::args().collect::<Vec<_>>().join(" "),
        scenario: scenario.name.clone(),
        mode: args.mode,
        perception: args.perception,
        namespace: lp.bus().topics().namespace().to_string(),
        ended: ended.unwrap_or_else(|| trace.end.clone()),
        interrupted: stopped_by.is_some(),
        collisions: sim.as_ref().map_or_else(|| egos.iter().map(|e| e.collisions).sum(), |s| s.ego_collisions),
        traffic_collisions: trace.traffic_collisions,
        sim_time_s,
        wall_time_s: started.elapsed().as_secs_f64(),
        sim_wall_time_s,
        real_time_factor: sim_time_s / sim_wall_time_s.max(1e-9),
        lockstep_timeouts: super::lockstep_timeouts(args, sim.as_ref()),
        nodes,
        own: lp.spec().own.clone(),
        latency: super::latency_report(&latency, args, time_gap, lag_s),
        metrics: None,
        sim: super::SimSource::Builtin,
        ground_truth: egos.iter().any(|e| e.metrics.as_ref().is_some_and(|m| m.min_gap_m.is_some())),
        topics,
        faults,
        inputs: Vec::new(),
        plots: egos.iter().map(|e| dir.join(format!("{}.png", e.namespace))).filter(|p| p.exists()).collect(),
        recording: None,
        view: None,
        ros2: None,
        ros2_recording: None,
        collisions_between_egos: sim.as_ref().map_or(0, |s| s.collisions_between_egos),
        egos,
        report_dir: dir.to_path_buf(),
    };
    super::written(report, lp, dir).await
}

/// The live view: the run's progress (the first ego's clock), a line per ego, the nodes.
fn view_lines(
    watches: &[(String, Watch)],
    name: &str,
    args: &UpArgs,
    duration_s: f64,
    alive: &[String],
) -> Vec<String> {
    let Some((_, first)) = watches.first() else { return Vec::new() };
    let mut lines = vec![first.progress_line(name, args.mode, Some(duration_s))];
    for (ns, w) in watches {
        let p99 = w.latency.lock().stats(true)[crate::observe::latency::WHOLE_LOOP].p99_ms;
        lines.push(format!("{ns:<6} {}  loop p99 {} ms", w.ego_line(), fmt_opt(p99, 1)));
    }
    let per_car = if args.perception == PerceptionSource::Camera { 2 } else { 1 };
    let cars = alive.iter().filter(|n| n.contains('/')).count();
    let sim = if alive.iter().any(|n| n == "sim") { "the simulator" } else { "no simulator yet" };
    lines.push(format!("nodes alive: {cars} of the cars' {}, {sim}", watches.len() * per_car));
    lines
}

/// The per-ego table of the summary.
pub fn table(egos: &[EgoReport], between: u64) -> String {
    let mut s = String::from(
        "\n  car     collisions  min gap m  min TTC s  time-gap RMS s  speed RMSE m/s  max decel m/s2  loop p99 ms  timeouts\n",
    );
    for e in egos {
        let h = e.metrics.as_ref().map(|m| m.headline());
        let col = |i: usize| h.as_ref().map_or("-".to_string(), |h| h[i].clone());
        s.push_str(&format!(
            "  {:<7} {:>10} {:>10} {:>10} {:>15} {:>15} {:>15} {:>12} {:>9}\n",
            e.namespace,
            e.collisions,
            col(0),
            col(1),
            col(2),
            col(3),
            col(5),
            fmt_opt(e.loop_p99_ms, 1),
            e.control.as_ref().map_or("-".to_string(), |c| c.lockstep_timeouts.to_string()),
        ));
    }
    s.push_str(&format!("  collisions between controlled vehicles: {between}\n"));
    s
}
