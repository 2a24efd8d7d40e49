//! The plots of a run: speeds, gaps and accelerations over time; the loop's latency per hop.
//! Drawn into an RGB buffer with plotters and saved as PNG through `image`.

use std::path::Path;

use crate::error::{Error, Result};

use super::trace::{Sample, Trace};
use slipstream_contract::msg::AccMode;
use slipstream_observe::latency::{LoopLatency, HOPS};

/// Font files tried for the plots' text, in order (`SLIPSTREAM_PLOT_FONT` first).
const FONT_PATHS: &[&str] = &[
    "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf",
    "/usr/share/fonts/TTF/DejaVuSans.ttf",
    "/usr/share/fonts/dejavu/DejaVuSans.ttf",
    "/usr/share/fonts/truetype/liberation/LiberationSans-Regular.ttf",
    "/Library/Fonts/Arial.ttf",
];

/// Whether a font for the plots' text is registered (looked for once per process).
fn font_registered() -> bool {
    static DONE: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    *DONE.get_or_init(|| {
        let from_env = std::env::var("SLIPSTREAM_PLOT_FONT").ok();
        let candidates = from_env.iter().map(String::as_str).chain(FONT_PATHS.iter().copied());
        for path in candidates {
            if let Ok(bytes) = std::fs::read(path) {
                let bytes: &'static [u8] = Box::leak(bytes.into_boxed_slice());
                if plotters::style::register_font("sans-serif", plotters::style::FontStyle::Normal, bytes).is_ok() {
                    return true;
                }
            }
        }
        false
    })
}

/// Registers the plots' font, or says how to get one.
pub(crate) fn register_font(path: &Path) -> Result<()> {
    match font_registered() {
        true => Ok(()),
        false => Err(Error::Plot {
            path: path.to_path_buf(),
            message: format!(
                "no TrueType font for the plots' text (tried {}); install one (e.g. apt-get install fonts-dejavu-core) or set SLIPSTREAM_PLOT_FONT=/path/to/font.ttf",
                FONT_PATHS.join(", ")
            ),
        }),
    }
}

/// What a drawing closure of the plots here returns: plotters' error on the bitmap backend.
pub type Drawn = std::result::Result<
    (),
    plotters::drawing::DrawingAreaErrorKind<
        <plotters::backend::BitMapBackend<'static> as plotters::prelude::DrawingBackend>::ErrorType,
    >,
>;

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
pub fn draw_legend<'a, 'b: 'a>(chart: &mut Chart<'a, 'b>) -> Drawn {
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

/// A white canvas of the plots here.
pub type Canvas<'a> = plotters::drawing::DrawingArea<plotters::backend::BitMapBackend<'a>, plotters::coord::Shift>;

/// The frame of every plot: the font, a white `(w, h)` canvas for `draw`, the PNG at `path`.
/// `draw` fails with any error that displays (plotters' own here, anyhow's in the tools).
pub fn png<E: std::fmt::Display>(
    path: &Path,
    (w, h): (u32, u32),
    draw: impl FnOnce(&Canvas<'_>) -> std::result::Result<(), E>,
) -> Result<()> {
    use plotters::prelude::*;
    register_font(path)?;
    let mut buf = vec![0u8; (w * h * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(Error::plot(path))?;
        draw(&root).map_err(Error::plot(path))?;
        root.present().map_err(Error::plot(path))?;
    }
    let img = image::RgbImage::from_raw(w, h, buf).ok_or_else(|| Error::plot(path)("the buffer is not w x h x 3"))?;
    img.save(path).map_err(Error::plot(path))?;
    Ok(())
}

/// Draws speeds, gaps and accelerations over time into a PNG.
pub fn plot(trace: &Trace, title: &str, path: &Path) -> Result<()> {
    use plotters::prelude::*;
    let (w, h) = (1100u32, 900u32);
    png(path, (w, h), |root| -> Drawn {
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
        let draw =
            |area: &DrawingArea<BitMapBackend, plotters::coord::Shift>, y_label: &str, lines: Vec<Line>| -> Drawn {
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
                            drawn.label(name).legend(move |(x, y)| {
                                PathElement::new(vec![(x, y), (x + 18, y)], color.stroke_width(2))
                            });
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
                ("lead (truth)", orange, series(&|x| x.lead_speed_mps())),
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
        Ok(())
    })
}

/// Loop latency per hop over the run.
pub fn plot_latency(lat: &LoopLatency, t0_ns: u64, title: &str, path: &Path) -> Result<()> {
    use plotters::prelude::*;
    let (w, h) = (1100u32, 500u32);
    let series: Vec<Vec<(f64, f64)>> = (0..HOPS.len()).map(|i| lat.series(i, t0_ns)).collect();
    let t_end = series.iter().flatten().map(|p| p.0).fold(1.0f64, f64::max);
    let hi = series.iter().flatten().map(|p| p.1).fold(1.0f64, f64::max) * 1.1;
    png(path, (w, h), |root| -> Drawn {
        let mut chart = ChartBuilder::on(root)
            .caption(title, ("sans-serif", 20))
            .margin(10)
            .x_label_area_size(40)
            .y_label_area_size(60)
            .build_cartesian_2d(0.0..t_end, 0.0..hi)?;
        chart.configure_mesh().x_desc("wall time (s)").y_desc("latency (ms)").label_style(("sans-serif", 14)).draw()?;
        let colors = [RGBColor(31, 119, 180), RGBColor(255, 127, 14), RGBColor(44, 160, 44), RGBColor(214, 39, 40)];
        for ((name, pts), color) in HOPS.iter().zip(series).zip(colors) {
            chart
                .draw_series(pts.into_iter().map(|p| Circle::new(p, 2, color.filled())))?
                .label(*name)
                .legend(move |(x, y)| Circle::new((x + 9, y), 4, color.filled()));
        }
        draw_legend(&mut chart)?;
        Ok(())
    })
}
