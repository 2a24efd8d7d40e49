//! `bench --plot FILE`: how the cost grows, one row of two panels per suite that ran (e. loops
//! side by side, f. camera fan-out, g. a router for several vehicles), against the count on a
//! log2 axis.

use std::path::Path;

use anyhow::Result;

use super::growth::FanoutPath;
use super::BenchReport;
use slipstream_eval::plot::{png, Canvas};

/// One line of a panel: its name, colour and points (count, value).
type Line = (String, plotters::style::RGBColor, Vec<(f64, f64)>);

/// A panel: title, y axis name, whether y is drawn on a log10 scale, its lines.
type Panel = (String, String, bool, Vec<Line>);

pub(crate) fn growth(report: &BenchReport, path: &Path) -> Result<()> {
    let rows: Vec<[Panel; 2]> =
        [scale_panels(report), fanout_panels(report), router_panels(report)].into_iter().flatten().collect();
    anyhow::ensure!(!rows.is_empty(), "--plot draws scale, fanout or router: run one of them");
    let (w, h) = (1300u32, 420 * rows.len() as u32 + 40);
    // The command without the binary's directory.
    let command = report.command.split_once(' ').map_or("slipstream bench", |(_, args)| args);
    png(path, (w, h), |root| -> Result<()> {
        let root = root.titled(&format!("How the cost grows (slipstream {command})"), ("sans-serif", 16))?;
        let areas = root.split_evenly((rows.len(), 2));
        for (i, panel) in rows.into_iter().flatten().enumerate() {
            draw_panel(&areas[i], panel)?;
        }
        Ok(())
    })?;
    Ok(())
}

/// e. Complete loops side by side: real-time factor and loop latency.
fn scale_panels(report: &BenchReport) -> Option<[Panel; 2]> {
    use plotters::prelude::*;
    let blue = RGBColor(31, 119, 180);
    let orange = RGBColor(255, 127, 14);
    let grey = RGBColor(140, 140, 140);
    if report.scale.is_empty() {
        return None;
    }
    let pts = |f: &dyn Fn(&super::scale::ScaleRow) -> Option<f64>| -> Vec<(f64, f64)> {
        report.scale.iter().filter_map(|r| f(r).map(|v| (r.loops as f64, v))).collect()
    };
    Some([
        (
            "e. complete loops side by side: real-time factor".into(),
            "real-time factor".into(),
            false,
            vec![
                ("slowest loop".into(), blue, pts(&|r| Some(r.rtf_min))),
                ("aim (real time)".into(), grey, pts(&|_| Some(super::scale::MIN_RTF))),
            ],
        ),
        (
            "e. frame published -> command applied".into(),
            "ms".into(),
            false,
            vec![
                ("p50 (median loop)".into(), blue, pts(&|r| r.loop_p50_ms)),
                ("p99 (worst loop)".into(), orange, pts(&|r| r.loop_p99_ms)),
                ("aim p50".into(), grey, pts(&|_| Some(super::scale::MAX_LOOP_P50_MS))),
            ],
        ),
    ])
}

/// f. Camera fan-out: frames/s per subscriber and latency at 20 Hz.
fn fanout_panels(report: &BenchReport) -> Option<[Panel; 2]> {
    use plotters::prelude::*;
    let blue = RGBColor(31, 119, 180);
    let orange = RGBColor(255, 127, 14);
    if report.fanout.is_empty() {
        return None;
    }
    let pts = |p: FanoutPath, f: &dyn Fn(&super::growth::FanoutRow) -> Option<f64>| -> Vec<(f64, f64)> {
        report.fanout.iter().filter(|r| r.path == p).filter_map(|r| f(r).map(|v| (r.subscribers as f64, v))).collect()
    };
    let (shm, router) = (FanoutPath::SharedMemory, FanoutPath::Router);
    Some([
        (
            "f. camera fan-out: frames/s each subscriber gets (slowest)".into(),
            "frames/s (log)".into(),
            true,
            vec![
                (shm.name().into(), blue, pts(shm, &|r| r.per_subscriber_min)),
                (router.name().into(), orange, pts(router, &|r| r.per_subscriber_min)),
            ],
        ),
        (
            "f. camera fan-out at 20 Hz: one-way latency p50".into(),
            "us".into(),
            false,
            vec![
                (shm.name().into(), blue, pts(shm, &|r| r.p50_us)),
                (router.name().into(), orange, pts(router, &|r| r.p50_us)),
            ],
        ),
    ])
}

/// g. A router for N vehicles: what it forwards, its CPU, and the latency through it.
fn router_panels(report: &BenchReport) -> Option<[Panel; 2]> {
    use plotters::prelude::*;
    let blue = RGBColor(31, 119, 180);
    let orange = RGBColor(255, 127, 14);
    let green = RGBColor(44, 160, 44);
    let grey = RGBColor(140, 140, 140);
    if report.router.is_empty() {
        return None;
    }
    let pts = |f: &dyn Fn(&super::growth::RouterRow) -> Option<f64>| -> Vec<(f64, f64)> {
        report.router.iter().filter(|r| r.via_router).filter_map(|r| f(r).map(|v| (r.vehicles as f64, v))).collect()
    };
    Some([
        (
            "g. a router for N vehicles: messages/s forwarded and its CPU".into(),
            "messages/s, CPU % x 10".into(),
            false,
            vec![
                ("messages/s".into(), blue, pts(&|r| Some(r.messages_per_s))),
                ("router CPU (% of a core x 10)".into(), green, pts(&|r| r.router_cpu_percent.map(|c| c * 10.0))),
            ],
        ),
        (
            "g. speed one-way through the router".into(),
            "us".into(),
            false,
            vec![
                ("p50".into(), blue, pts(&|r| r.speed_p50_us)),
                ("added p50 (vs direct)".into(), orange, pts(&|r| r.added_p50_us)),
                ("control p50".into(), grey, pts(&|r| r.control_p50_us)),
            ],
        ),
    ])
}

/// Counts on a log2 axis (labelled 1, 2, 4, ...), values linear or on a log10 axis: the
/// points are drawn as (log2 count, value or log10 value) and the labels turned back.
fn draw_panel(area: &Canvas<'_>, (title, y_desc, log_y, lines): Panel) -> Result<()> {
    use plotters::prelude::*;
    let to_y = |v: f64| if log_y { v.max(1e-9).log10() } else { v };
    let lines: Vec<Line> = lines
        .into_iter()
        .map(|(n, c, pts)| (n, c, pts.into_iter().map(|(x, y)| (x.max(1.0).log2(), to_y(y))).collect()))
        .collect();
    let points = || lines.iter().flat_map(|l| l.2.iter().copied());
    let x_max = points().map(|p| p.0).fold(1.0f64, f64::max);
    let (y_lo, y_hi) = points().fold((f64::MAX, f64::MIN), |(lo, hi), p| (lo.min(p.1), hi.max(p.1)));
    let (y_lo, y_hi) = match (log_y, y_lo <= y_hi) {
        (true, true) => (y_lo.floor(), y_hi.ceil().max(y_lo.floor() + 1.0)),
        (false, true) => (0.0, (y_hi * 1.15).max(1e-3)),
        (_, false) => (0.0, 1.0),
    };
    let mut chart = ChartBuilder::on(area)
        .caption(title, ("sans-serif", 16))
        .margin(10)
        .x_label_area_size(40)
        .y_label_area_size(70)
        .build_cartesian_2d(-0.1..x_max + 0.1, y_lo..y_hi)?;
    // Labels at whole powers of two only (the counts the suites use).
    let x_label = |x: &f64| match (x - x.round()).abs() < 1e-6 {
        true => format!("{}", 2f64.powf(*x).round()),
        false => String::new(),
    };
    let y_label = |y: &f64| match log_y {
        true => format!("{}", 10f64.powf(*y).round()),
        false => format!("{y}"),
    };
    chart
        .configure_mesh()
        .disable_x_mesh()
        .light_line_style(WHITE)
        .x_labels(x_max.round() as usize + 1)
        .x_label_formatter(&x_label)
        .y_labels(if log_y { (y_hi - y_lo) as usize + 1 } else { 8 })
        .y_label_formatter(&y_label)
        .x_desc("count")
        .y_desc(y_desc)
        .label_style(("sans-serif", 13))
        .draw()?;
    for (name, color, pts) in lines {
        if pts.is_empty() {
            continue;
        }
        chart
            .draw_series(LineSeries::new(pts.clone(), color.stroke_width(2)))?
            .label(name)
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], color.stroke_width(2)));
        chart.draw_series(pts.into_iter().map(|p| Circle::new(p, 3, color.filled())))?;
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .label_font(("sans-serif", 13))
        .position(SeriesLabelPosition::UpperLeft)
        .draw()?;
    Ok(())
}
