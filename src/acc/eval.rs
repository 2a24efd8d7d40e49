//! Judging the ACC: the figures of one run (from the simulator's ground truth, not from the
//! ACC's own view), pass/fail against the aims, and the plot of a run.
//!
//! A run is a [`Trace`]: one [`Sample`] per vehicle/state message (every physics step by
//! default) with the ego's motion, the ACC's status and the true lead in the ego's lane.

use std::path::Path;

use serde::Serialize;

use crate::msg::{AccMode, AccStatus, GroundTruthObjects, VehicleState};

/// The true lead: the nearest vehicle ahead whose centre is in the ego's lane.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct TruthLead {
    pub id: u32,
    /// Bumper to bumper.
    pub gap_m: f64,
    /// Lead speed minus ego speed along ego x.
    pub relative_speed_mps: f64,
}

pub fn truth_lead(gt: &GroundTruthObjects, ego_lane: i32, ego_front_m: f64) -> Option<TruthLead> {
    gt.objects
        .iter()
        .filter(|o| o.lane == ego_lane && ego_lane >= 0 && o.position_in_ego_m[0] > 0.0)
        .min_by(|a, b| a.position_in_ego_m[0].total_cmp(&b.position_in_ego_m[0]))
        .map(|o| TruthLead {
            id: o.id,
            gap_m: o.position_in_ego_m[0] - ego_front_m,
            relative_speed_mps: o.velocity_in_ego_mps[0],
        })
}

#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Sample {
    pub t_s: f64,
    pub speed_mps: f64,
    pub accel_mps2: f64,
    pub mode: AccMode,
    pub target_accel_mps2: f64,
    pub set_speed_mps: f64,
    pub time_gap_s: f64,
    /// The gap the ACC measured to its lead.
    pub acc_gap_m: Option<f64>,
    pub truth: Option<TruthLead>,
}

impl Sample {
    pub fn new(t_s: f64, state: &VehicleState, status: &AccStatus, truth: Option<TruthLead>) -> Self {
        Sample {
            t_s,
            speed_mps: state.speed_mps,
            accel_mps2: state.acceleration_in_body_mps2[0],
            mode: status.mode,
            target_accel_mps2: status.target_accel_mps2,
            set_speed_mps: status.set_speed_mps,
            time_gap_s: status.time_gap_s,
            acc_gap_m: status.lead.map(|l| l.gap_m),
            truth,
        }
    }
}

/// One run of a scenario.
#[derive(Debug, Clone, Default, Serialize)]
pub struct Trace {
    pub standstill_m: f64,
    pub samples: Vec<Sample>,
    pub collisions: u64,
    /// Why the scenario ended.
    pub end: String,
}

/// The aims of issue 5 (docs/control.md).
pub mod aims {
    pub const TIME_GAP_RMS_S: f64 = 0.1;
    pub const MAX_ACCEL_MPS2: f64 = 2.0;
    pub const MAX_DECEL_MPS2: f64 = 3.5;
    pub const MAX_JERK_MPS3: f64 = 2.5;
    /// Tolerance on the measured comfort figures: the vehicle's response to a limited target
    /// overshoots a little (tyre and suspension dynamics of the physics engine).
    pub const COMFORT_TOLERANCE: f64 = 0.1;
}

/// How long a stretch must last before it counts as steady.
const STEADY_S: f64 = 10.0;
/// Samples this close (before, after) to an emergency belong to it.
const EMERGENCY_MARGIN_S: (f64, f64) = (0.1, 1.5);
/// Jerk is taken over this window of measured acceleration.
const JERK_WINDOW_S: f64 = 0.1;
/// Below this speed comfort is not judged: a car stopping on its brakes has a jerk spike at the
/// instant it stops, and ISO 15622 puts its jerk limit on driving at speed.
const COMFORT_MIN_SPEED_MPS: f64 = 2.0;
/// The first moments of a run belong to the simulator: until the controller's first command
/// arrives the ego cruises (realtime runs), so the step to the controller's acceleration is
/// the handover, not the controller's comfort. Jerk is judged from here on.
const HANDOVER_S: f64 = 0.2;

#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Check {
    pub name: String,
    pub value: Option<f64>,
    pub aim: String,
    pub pass: bool,
}

#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Metrics {
    pub duration_s: f64,
    pub collisions: u64,
    pub min_gap_m: Option<f64>,
    pub min_ttc_s: Option<f64>,
    pub time_gap_rms_error_s: Option<f64>,
    /// Simulated seconds of steady following the time-gap error was taken over.
    pub steady_follow_s: f64,
    pub speed_rmse_mps: Option<f64>,
    pub steady_speed_s: f64,
    pub max_accel_mps2: f64,
    /// Outside emergencies and at speed.
    pub max_decel_mps2: f64,
    pub max_jerk_mps3: f64,
    pub emergency_s: f64,
    pub max_decel_in_emergency_mps2: f64,
    pub checks: Vec<Check>,
    pub pass: bool,
}

fn rms(v: &[f64]) -> Option<f64> {
    (!v.is_empty()).then(|| (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt())
}

impl Metrics {
    pub fn of(trace: &Trace) -> Metrics {
        let s = &trace.samples;
        let dt = if s.len() > 1 { (s[s.len() - 1].t_s - s[0].t_s) / (s.len() - 1) as f64 } else { 0.01 };
        let emergency_times: Vec<f64> = s.iter().filter(|x| x.mode == AccMode::Emergency).map(|x| x.t_s).collect();
        // From a little before an emergency to a while after it (the release).
        let near_emergency =
            |t: f64| emergency_times.iter().any(|&e| e >= t - EMERGENCY_MARGIN_S.1 && e <= t + EMERGENCY_MARGIN_S.0);

        let mut min_gap: Option<f64> = None;
        let mut min_ttc: Option<f64> = None;
        let (mut gap_errors, mut speed_errors) = (Vec::new(), Vec::new());
        let (mut max_accel, mut max_decel, mut max_jerk, mut max_em_decel) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
        // Start of the current stretch with the same truth lead (steady lead speed), and of the
        // current stretch in speed mode at the same set speed.
        let mut lead_since: Option<(u32, usize)> = None;
        let mut speed_since: Option<(f64, usize)> = None;
        let jerk_lag = (JERK_WINDOW_S / dt.max(1e-6)).round().max(1.0) as usize;
        for (i, x) in s.iter().enumerate() {
            if let Some(tl) = x.truth {
                min_gap = Some(min_gap.map_or(tl.gap_m, |m| m.min(tl.gap_m)));
                if -tl.relative_speed_mps > 0.1 {
                    let ttc = tl.gap_m.max(0.0) / -tl.relative_speed_mps;
                    min_ttc = Some(min_ttc.map_or(ttc, |m| m.min(ttc)));
                }
                if lead_since.is_none_or(|(id, _)| id != tl.id) {
                    lead_since = Some((tl.id, i));
                }
            } else {
                lead_since = None;
            }
            if let Some((_, from)) = lead_since {
                let window = &s[from..=i];
                // Steady following: the same lead for 2 x STEADY_S (time to settle), its speed
                // within 1 m/s over the last STEADY_S. What the ego does meanwhile is judged.
                let steady_lead = x.t_s - s[from].t_s >= 2.0 * STEADY_S && {
                    let range = |f: &dyn Fn(&Sample) -> f64| {
                        let (lo, hi) = window
                            .iter()
                            .filter(|w| w.t_s >= x.t_s - STEADY_S)
                            .map(f)
                            .fold((f64::MAX, f64::MIN), |(lo, hi), v| (lo.min(v), hi.max(v)));
                        hi - lo
                    };
                    let lead_speed = |w: &Sample| w.speed_mps + w.truth.map_or(0.0, |t| t.relative_speed_mps);
                    range(&lead_speed) < 1.0
                };
                if steady_lead && x.mode == AccMode::Follow && x.speed_mps > 3.0 {
                    let tl = x.truth.expect("lead stretch");
                    gap_errors.push((tl.gap_m - trace.standstill_m) / x.speed_mps - x.time_gap_s);
                }
            }
            if x.mode == AccMode::Speed {
                if speed_since.is_none_or(|(v, _)| v != x.set_speed_mps) {
                    speed_since = Some((x.set_speed_mps, i));
                }
                if let Some((_, from)) = speed_since {
                    if x.t_s - s[from].t_s >= STEADY_S {
                        speed_errors.push(x.speed_mps - x.set_speed_mps);
                    }
                }
            } else {
                speed_since = None;
            }
            if x.mode == AccMode::Emergency {
                max_em_decel = max_em_decel.max(-x.accel_mps2);
            }
            if !near_emergency(x.t_s) && x.speed_mps >= COMFORT_MIN_SPEED_MPS {
                max_accel = max_accel.max(x.accel_mps2);
                max_decel = max_decel.max(-x.accel_mps2);
                if i >= jerk_lag
                    && s[i - jerk_lag].speed_mps >= COMFORT_MIN_SPEED_MPS
                    && s[i - jerk_lag].t_s - s[0].t_s >= HANDOVER_S
                {
                    let p = &s[i - jerk_lag];
                    let j = (x.accel_mps2 - p.accel_mps2) / (x.t_s - p.t_s).max(1e-6);
                    max_jerk = max_jerk.max(j.abs());
                }
            }
        }
        let time_gap_rms = rms(&gap_errors);
        let speed_rmse = rms(&speed_errors);
        let tol = 1.0 + aims::COMFORT_TOLERANCE;
        let mut checks = vec![
            Check {
                name: "collisions".into(),
                value: Some(trace.collisions as f64),
                aim: "0".into(),
                pass: trace.collisions == 0,
            },
            Check {
                name: "min gap (m)".into(),
                value: min_gap,
                aim: "> 0".into(),
                pass: min_gap.is_none_or(|g| g > 0.0),
            },
        ];
        if let Some(e) = time_gap_rms {
            checks.push(Check {
                name: "time-gap RMS error, steady following (s)".into(),
                value: Some(e),
                aim: format!("<= {}", aims::TIME_GAP_RMS_S),
                pass: e <= aims::TIME_GAP_RMS_S,
            });
        }
        checks.push(Check {
            name: "max accel outside emergencies (m/s2)".into(),
            value: Some(max_accel),
            aim: format!("<= {} (+{:.0}%)", aims::MAX_ACCEL_MPS2, aims::COMFORT_TOLERANCE * 100.0),
            pass: max_accel <= aims::MAX_ACCEL_MPS2 * tol,
        });
        checks.push(Check {
            name: "max decel outside emergencies (m/s2)".into(),
            value: Some(max_decel),
            aim: format!("<= {} (+{:.0}%)", aims::MAX_DECEL_MPS2, aims::COMFORT_TOLERANCE * 100.0),
            pass: max_decel <= aims::MAX_DECEL_MPS2 * tol,
        });
        checks.push(Check {
            name: "max jerk outside emergencies (m/s3)".into(),
            value: Some(max_jerk),
            aim: format!("<= {} (+{:.0}%)", aims::MAX_JERK_MPS3, aims::COMFORT_TOLERANCE * 100.0),
            pass: max_jerk <= aims::MAX_JERK_MPS3 * tol,
        });
        let pass = checks.iter().all(|c| c.pass);
        Metrics {
            duration_s: s.last().map_or(0.0, |x| x.t_s),
            collisions: trace.collisions,
            min_gap_m: min_gap,
            min_ttc_s: min_ttc,
            time_gap_rms_error_s: time_gap_rms,
            steady_follow_s: gap_errors.len() as f64 * dt,
            speed_rmse_mps: speed_rmse,
            steady_speed_s: speed_errors.len() as f64 * dt,
            max_accel_mps2: max_accel,
            max_decel_mps2: max_decel,
            max_jerk_mps3: max_jerk,
            emergency_s: emergency_times.len() as f64 * dt,
            max_decel_in_emergency_mps2: max_em_decel,
            checks,
            pass,
        }
    }
}

/// Font files tried for the plots' text, in order (`SLIPSTREAM_PLOT_FONT` first).
const FONT_PATHS: &[&str] = &[
    "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf",
    "/usr/share/fonts/TTF/DejaVuSans.ttf",
    "/usr/share/fonts/dejavu/DejaVuSans.ttf",
    "/usr/share/fonts/truetype/liberation/LiberationSans-Regular.ttf",
    "/Library/Fonts/Arial.ttf",
];

pub(crate) fn register_font() -> anyhow::Result<()> {
    static DONE: std::sync::OnceLock<Result<(), String>> = std::sync::OnceLock::new();
    DONE.get_or_init(|| {
        let from_env = std::env::var("SLIPSTREAM_PLOT_FONT").ok();
        let candidates = from_env.iter().map(String::as_str).chain(FONT_PATHS.iter().copied());
        for path in candidates {
            if let Ok(bytes) = std::fs::read(path) {
                let bytes: &'static [u8] = Box::leak(bytes.into_boxed_slice());
                if plotters::style::register_font("sans-serif", plotters::style::FontStyle::Normal, bytes).is_ok() {
                    return Ok(());
                }
            }
        }
        Err(format!(
            "no TrueType font for the plots' text (tried {}); install one (e.g. apt-get install fonts-dejavu-core) or set SLIPSTREAM_PLOT_FONT=/path/to/font.ttf",
            FONT_PATHS.join(", ")
        ))
    })
    .clone()
    .map_err(anyhow::Error::msg)
}

/// Draws speeds, gaps and accelerations over time into a PNG.
/// A time-series chart of the plots here.
pub(crate) type Chart<'a, 'b> = plotters::chart::ChartContext<
    'a,
    plotters::backend::BitMapBackend<'b>,
    plotters::coord::cartesian::Cartesian2d<
        plotters::coord::types::RangedCoordf64,
        plotters::coord::types::RangedCoordf64,
    >,
>;

/// The legend, the same on every plot: upper right, on a light box.
pub(crate) fn draw_legend<'a, 'b: 'a>(chart: &mut Chart<'a, 'b>) -> anyhow::Result<()> {
    use plotters::prelude::*;
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .label_font(("sans-serif", 14))
        .position(SeriesLabelPosition::UpperRight)
        .draw()?;
    Ok(())
}

pub fn plot(trace: &Trace, title: &str, path: &Path) -> anyhow::Result<()> {
    use plotters::prelude::*;
    register_font()?;
    let (w, h) = (1100u32, 900u32);
    let mut buf = vec![0u8; (w * h * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
        root.fill(&WHITE)?;
        let root = root.titled(title, ("sans-serif", 22))?;
        let panels = root.split_evenly((3, 1));
        let s = &trace.samples;
        let t_end = s.last().map_or(1.0, |x| x.t_s).max(1.0);
        let series = |f: &dyn Fn(&Sample) -> Option<f64>| -> Vec<Vec<(f64, f64)>> {
            // Broken where the value is missing, so a vanished lead leaves a hole.
            let mut out: Vec<Vec<(f64, f64)>> = vec![Vec::new()];
            for x in s {
                match f(x) {
                    Some(v) => out.last_mut().expect("one").push((x.t_s, v)),
                    None if !out.last().expect("one").is_empty() => out.push(Vec::new()),
                    None => {}
                }
            }
            out
        };
        type Line<'a> = (&'a str, RGBColor, Vec<Vec<(f64, f64)>>);
        let draw = |area: &DrawingArea<BitMapBackend, plotters::coord::Shift>,
                    y_label: &str,
                    lines: Vec<Line>|
         -> anyhow::Result<()> {
            let values = lines.iter().flat_map(|l| l.2.iter().flatten().map(|p| p.1));
            let (lo, hi) = values.fold((f64::MAX, f64::MIN), |(lo, hi), v| (lo.min(v), hi.max(v)));
            let (lo, hi) = if lo > hi { (0.0, 1.0) } else { (lo, hi) };
            let pad = ((hi - lo) * 0.08).max(0.5);
            let mut chart = ChartBuilder::on(area)
                .margin(8)
                .x_label_area_size(40)
                .y_label_area_size(60)
                .build_cartesian_2d(0.0..t_end, (lo - pad)..(hi + pad))?;
            chart
                .configure_mesh()
                .x_desc("simulated time (s)")
                .y_desc(y_label)
                .label_style(("sans-serif", 14))
                .draw()?;
            for (name, color, parts) in lines {
                let mut first = true;
                for part in parts {
                    let drawn = chart.draw_series(LineSeries::new(part, color.stroke_width(2)))?;
                    if first {
                        drawn
                            .label(name)
                            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], color.stroke_width(2)));
                        first = false;
                    }
                }
            }
            draw_legend(&mut chart)?;
            Ok(())
        };
        let blue = RGBColor(31, 119, 180);
        let orange = RGBColor(255, 127, 14);
        let green = RGBColor(44, 160, 44);
        let grey = RGBColor(140, 140, 140);
        let red = RGBColor(214, 39, 40);
        draw(
            &panels[0],
            "speed (m/s)",
            vec![
                ("ego", blue, series(&|x| Some(x.speed_mps))),
                ("lead (truth)", orange, series(&|x| x.truth.map(|t| x.speed_mps + t.relative_speed_mps))),
                ("set speed", grey, series(&|x| Some(x.set_speed_mps))),
            ],
        )?;
        draw(
            &panels[1],
            "gap (m)",
            vec![
                ("gap (truth)", blue, series(&|x| x.truth.map(|t| t.gap_m))),
                ("desired gap", grey, series(&|x| Some(trace.standstill_m + x.time_gap_s * x.speed_mps))),
                ("gap (ACC)", green, series(&|x| x.acc_gap_m)),
            ],
        )?;
        draw(
            &panels[2],
            "acceleration (m/s2)",
            vec![
                ("ego", blue, series(&|x| Some(x.accel_mps2))),
                ("ACC target", orange, series(&|x| Some(x.target_accel_mps2))),
                ("emergency", red, series(&|x| (x.mode == AccMode::Emergency).then_some(x.target_accel_mps2))),
            ],
        )?;
        root.present()?;
    }
    let img = image::RgbImage::from_raw(w, h, buf).ok_or_else(|| anyhow::anyhow!("plot buffer size"))?;
    img.save(path).map_err(|e| anyhow::anyhow!("write {}: {e}", path.display()))?;
    Ok(())
}
