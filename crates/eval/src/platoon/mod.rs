//! `slipstream eval platoon`: a platoon's string stability measured on the bus. For each time
//! gap asked, the platoon scenario starts in that gap's equilibrium and runs in lockstep with
//! every ego's own ACC process (and detector with the camera); the figures ([`figures`]) say
//! how the leader's disturbance grows or fades car by car. The smallest time gap measured
//! stable is set against the analytic bound `up` prints, 2 x (loop delay + actuator lag).

pub mod figures;
pub mod links;
pub mod run;

use std::path::{Path, PathBuf};

use serde::Serialize;

use crate::error::{Error, Result};
use figures::{string_figures, StringFigures};
use links::Links;
use slipstream_acc::settings::AccSettings;
use slipstream_acc::PerceptionSource;
use slipstream_model::vehicle::VehicleParams;
use slipstream_sim::SimSettings;

#[derive(Debug, Clone, clap::Args)]
pub struct EvalPlatoonArgs {
    /// A platoon: a built-in one (platoon-8, platoon-8-hard-brake, platoon-8-stop-and-go) or a
    /// scenario file with `egos` (its first scripted vehicle leads)
    #[arg(long, default_value = "platoon-8")]
    pub scenario: String,
    /// Time gaps to measure at, seconds, comma-separated (every ego's ACC set to each in turn)
    #[arg(long, value_delimiter = ',', default_value = "0.8,1.2,1.8,2.4")]
    pub time_gaps: Vec<f64>,
    /// Where the vehicles ahead come from: ground-truth (control alone) or camera (a detector
    /// per car)
    #[arg(long, value_enum, default_value = "ground-truth")]
    pub perception: PerceptionSource,
    /// Simulated seconds of each run instead of the scenario's
    #[arg(long)]
    pub duration: Option<f64>,
    /// Where the runs' scenarios, logs, platoon.json and platoon.png go [default:
    /// reports/platoon-<scenario>-<UTC date>-<time>]
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// Print the report as JSON instead of tables
    #[arg(long)]
    pub json: bool,
    /// Every node injects the profile's faults into what it receives: each car's ACC (and
    /// detector) on its own links, the simulator on the commands (docs/faults.md; lockstep
    /// refuses faults on vehicle/speed and camera/front)
    #[command(flatten)]
    pub faults: slipstream_contract::config::FaultArgs,
    /// Every message through a Zenoh router, every node its client with shared memory off:
    /// `--router` alone starts `slipstream router` on a free loopback port for the runs;
    /// `--router tcp/HOST:7447` uses one already running (zenohd, or a router on another PC).
    /// In lockstep the figures do not depend on the links; the wall time does
    #[arg(long, value_name = "ENDPOINT", num_args = 0..=1, default_missing_value = "")]
    pub router: Option<String>,
    /// The simulator's clock: lockstep (every car's command awaited at every step, so the
    /// figures are the control's alone) or realtime (the loop's wall-clock latency delays
    /// every car as on the road, and the bound takes the first car's measured p99 latency;
    /// each run takes its duration)
    #[arg(long, value_enum, default_value = "lockstep")]
    pub mode: PlatoonClock,
}

/// `eval platoon --mode`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum PlatoonClock {
    Lockstep,
    Realtime,
}

/// One time gap's run.
#[derive(Debug, Clone, Serialize)]
pub struct AtGap {
    #[serde(flatten)]
    pub figures: StringFigures,
    /// Collisions of the controlled cars (any ends the run).
    pub collisions: u64,
    pub lockstep_timeouts: u64,
    /// Simulated over wall seconds of the run (the links' cost shows here, not in the figures).
    pub real_time_factor: f64,
    /// In realtime, the first car's loop latency p99 (frame or ground truth -> command applied).
    pub loop_p99_ms: Option<f64>,
}

#[derive(Debug, Clone, Serialize)]
pub struct PlatoonReport {
    pub scenario: String,
    pub perception: &'static str,
    /// The simulator's clock: lockstep or realtime.
    pub clock: &'static str,
    pub cars: usize,
    /// When the leader's disturbance began (simulated s): the figures are taken from it on.
    pub disturbance_s: f64,
    pub runs: Vec<AtGap>,
    /// The smallest time gap measured stable, when one was.
    pub smallest_stable_time_gap_s: Option<f64>,
    /// The analytic bound: 2 x (delay + actuator lag).
    pub bound_s: f64,
    /// The loop's delay: in lockstep one state period (a command acts one state period after
    /// the state it answers), in realtime the largest of the runs' measured p99 latencies.
    pub delay_s: f64,
    pub actuator_lag_s: f64,
    /// Whether every gap measured above the bound was stable (the bound held as a sufficient
    /// condition for this ACC).
    pub bound_holds: bool,
    /// The fault profile every node injected (`--faults`), if any.
    pub faults: Option<String>,
    /// The router every message crossed (`--router`), if any.
    pub router: Option<String>,
}

/// Runs the platoon at every time gap in turn.
pub async fn measure(args: &EvalPlatoonArgs, dir: &Path) -> Result<PlatoonReport> {
    let realtime = args.mode == PlatoonClock::Realtime;
    let value = run::scenario_value(&args.scenario)?;
    let standstill = AccSettings::load_or_default(None)?.standstill_m;
    let sim = SimSettings::load_or_default(None)?;
    let faults = match args.faults.profile()? {
        Some(p) => {
            if !realtime {
                slipstream_launch::refuse_in_lockstep(&p)?;
            }
            std::fs::create_dir_all(dir).map_err(|source| Error::File {
                action: "create",
                path: dir.into(),
                source,
            })?;
            let file = dir.join("faults.json5");
            std::fs::write(&file, p.to_json5()).map_err(|source| Error::File {
                action: "write",
                path: file.clone(),
                source,
            })?;
            Some((file, p.summary()))
        }
        None => None,
    };
    std::fs::create_dir_all(dir).map_err(|source| Error::File { action: "create", path: dir.into(), source })?;
    let links = Links::from_arg(args.router.as_deref(), &dir.join("router.log"))?;
    let faults_file = faults.as_ref().map(|f| f.0.as_path());
    let nodes = run::Nodes { perception: args.perception, faults: faults_file, links: &links, realtime };
    let mut runs = Vec::new();
    let (mut name, mut cars, mut from_s, mut lag) = (args.scenario.clone(), 0, 0.0, 0.0);
    for &h in &args.time_gaps {
        let (scenario, text) = run::at_time_gap(value.clone(), h, standstill, args.duration)?;
        let at = dir.join(format!("gap-{h}"));
        std::fs::create_dir_all(&at).map_err(|source| Error::File { action: "create", path: at.clone(), source })?;
        let file = at.join("scenario.json5");
        std::fs::write(&file, text).map_err(|source| Error::File { action: "write", path: file.clone(), source })?;
        (name, cars, from_s) = (scenario.name.clone(), scenario.egos().len(), run::disturbance_s(&scenario));
        lag = VehicleParams::of_class(scenario.ego().class.into()).actuator_lag_s;
        tracing::info!(time_gap_s = h, "platoon run");
        let r = run::run(&scenario, &file, &nodes, &at).await?;
        runs.push(AtGap {
            figures: string_figures(h, &r.leader, &r.cars, from_s),
            collisions: r.sim.ego_collisions,
            lockstep_timeouts: r.sim.lockstep_timeouts,
            real_time_factor: r.sim.real_time_factor,
            loop_p99_ms: r.loop_p99_s.map(|s| s * 1e3),
        });
    }
    let measured =
        runs.iter().filter_map(|r| r.loop_p99_ms).fold(None, |m: Option<f64>, x| Some(m.map_or(x, |m| m.max(x))));
    let delay_s = measured.map_or(1.0 / sim.rates_hz.state, |ms| ms / 1e3);
    let bound_s = 2.0 * (delay_s + lag);
    let stable = |r: &&AtGap| r.figures.stable && r.collisions == 0;
    let smallest = runs
        .iter()
        .filter(stable)
        .map(|r| r.figures.time_gap_s)
        .fold(None, |m: Option<f64>, h| Some(m.map_or(h, |m| m.min(h))));
    let bound_holds = runs.iter().filter(|r| r.figures.time_gap_s > bound_s).all(|r| stable(&r));
    Ok(PlatoonReport {
        scenario: name,
        perception: args.perception.name(),
        clock: if realtime { "realtime" } else { "lockstep" },
        cars,
        disturbance_s: from_s,
        runs,
        smallest_stable_time_gap_s: smallest,
        bound_s,
        delay_s,
        actuator_lag_s: lag,
        bound_holds,
        faults: faults.map(|f| f.1),
        router: links.router().map(String::from),
    })
}

/// The report as tables: per time gap, each car's peak speed error and deceleration with their
/// ratios to the car ahead, then the verdict against the bound.
pub fn markdown(r: &PlatoonReport) -> String {
    let mut s = format!(
        "# slipstream eval platoon: {} ({} cars, {} perception, {} clock; figures from t = {:.1} s)\n",
        r.scenario, r.cars, r.perception, r.clock, r.disturbance_s
    );
    if let Some(f) = &r.faults {
        s.push_str(&format!("\nfaults injected at every node: {f}\n"));
    }
    if let Some(router) = &r.router {
        s.push_str(&format!("\nevery message through the router at {router} (every node its client)\n"));
    }
    for run in &r.runs {
        let f = &run.figures;
        let verdict = if f.stable && run.collisions == 0 { "string-stable" } else { "NOT string-stable" };
        s.push_str(&format!(
            "\n## time gap {:.2} s: {verdict} (largest speed-error ratio {}; collisions {}, lockstep timeouts {}; real-time factor {:.2}{})\n\n",
            f.time_gap_s, ratio_text(f.max_speed_ratio), run.collisions, run.lockstep_timeouts, run.real_time_factor,
            run.loop_p99_ms.map_or(String::new(), |ms| format!("; car 1's loop p99 {ms:.1} ms"))
        ));
        s.push_str("| car | peak speed error m/s | ratio | peak decel m/s2 | ratio |\n|---|---|---|---|---|\n");
        for c in &f.cars {
            let ratio = |x: Option<f64>| x.map_or("-".to_string(), ratio_text);
            s.push_str(&format!(
                "| {} | {:.2} | {} | {:.2} | {} |\n",
                c.car,
                c.peak_speed_error_mps,
                ratio(c.speed_ratio),
                c.peak_decel_mps2,
                ratio(c.decel_ratio)
            ));
        }
    }
    let smallest = r.smallest_stable_time_gap_s.map_or("none of those measured".into(), |h| format!("{h:.2} s"));
    s.push_str(&format!(
        "\nsmallest string-stable time gap measured: {smallest}; analytic bound 2 x (delay {:.3} s + actuator lag {:.3} s) = {:.3} s: {}\n",
        r.delay_s,
        r.actuator_lag_s,
        r.bound_s,
        if r.bound_holds { "every gap above it measured stable (agrees)" } else { "a gap above it measured unstable (disagrees: this ACC needs more than the bound)" }
    ));
    s
}

/// platoon.png: each car's peak speed error by its place in the string (0: the leader), one
/// line per time gap; a line that climbs is a disturbance that grows.
pub fn plot(r: &PlatoonReport, path: &Path) -> Result<()> {
    use super::plot::{draw_legend, png, Drawn};
    use plotters::prelude::*;
    let hi = r.runs.iter().flat_map(|x| &x.figures.cars).map(|c| c.peak_speed_error_mps).fold(0.5f64, f64::max) * 1.15;
    let n = r.cars as f64;
    let title = format!("{}: the leader's disturbance along the string ({} perception)", r.scenario, r.perception);
    png(path, (1000, 520), |root| -> Drawn {
        let mut chart = ChartBuilder::on(root)
            .caption(title, ("sans-serif", 20))
            .margin(10)
            .x_label_area_size(40)
            .y_label_area_size(60)
            .build_cartesian_2d(-0.2..n + 0.2, 0.0..hi)?;
        chart
            .configure_mesh()
            .x_desc("place in the string (0: leader)")
            .y_desc("peak speed error (m/s)")
            .label_style(("sans-serif", 14))
            .draw()?;
        // The bound: no car's error above the car ahead's, so none above the leader's.
        if let Some(leader) =
            r.runs.iter().filter_map(|x| x.figures.cars.first()).map(|c| c.peak_speed_error_mps).reduce(f64::max)
        {
            let grey = RGBColor(120, 120, 120);
            chart
                .draw_series(LineSeries::new(vec![(-0.2, leader), (n + 0.2, leader)], grey.stroke_width(1)))?
                .label("the leader's peak: a string-stable platoon stays at or below it")
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], grey.stroke_width(1)));
        }
        for (i, run) in r.runs.iter().enumerate() {
            let color = Palette99::pick(i).to_rgba();
            let points: Vec<(f64, f64)> =
                run.figures.cars.iter().enumerate().map(|(k, c)| (k as f64, c.peak_speed_error_mps)).collect();
            let stable = if run.figures.stable && run.collisions == 0 { "stable" } else { "unstable" };
            chart
                .draw_series(LineSeries::new(points.clone(), color.stroke_width(2)))?
                .label(format!("time gap {:.1} s ({stable})", run.figures.time_gap_s))
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], color.stroke_width(2)));
            chart.draw_series(points.into_iter().map(|p| Circle::new(p, 3, color.filled())))?;
        }
        draw_legend(&mut chart)?;
        Ok(())
    })
}

/// A ratio to 1 with the digits that show which side of 1 it is on, the criterion being
/// "at most 1": three decimals, more where three would round it to 1.000.
fn ratio_text(x: f64) -> String {
    (3..=9)
        .map(|digits| format!("{x:.digits$}"))
        .find(|t| x == 1.0 || t.parse::<f64>().is_ok_and(|r| r != 1.0))
        .unwrap_or_else(|| format!("{x}"))
}

#[cfg(test)]
mod tests {
    use super::ratio_text;

    #[test]
    fn a_ratio_shows_which_side_of_one_it_is_on() {
        assert_eq!(ratio_text(0.987), "0.987");
        assert_eq!(ratio_text(1.011), "1.011");
        assert_eq!(ratio_text(1.0004), "1.0004", "three decimals would say 1.000: not stable");
        assert_eq!(ratio_text(0.99996), "0.99996");
        assert_eq!(ratio_text(1.0), "1.000");
    }
}
