//! The sweep's plot: per family, the rates per 1,000 km a driver would meet (collisions,
//! unwarranted emergencies, phantom-braking events), as grouped bars.

use std::path::Path;

use super::rates::Rates;
use crate::error::Result;
use crate::plot::{draw_legend, png, Drawn};

/// Draws the rates of `families` into a PNG at `path`.
pub fn rates(families: &[Rates], path: &Path) -> Result<()> {
    use plotters::prelude::*;
    /// A bar: its label, its colour and the rate it shows.
    type Bar = (&'static str, RGBColor, fn(&Rates) -> f64);
    let bars: [Bar; 3] = [
        ("collisions", RGBColor(200, 30, 30), |r| r.per_1000_km.collisions),
        ("unwarranted emergencies", RGBColor(230, 140, 20), |r| r.per_1000_km.unwarranted_emergencies),
        ("phantom-braking events", RGBColor(40, 90, 200), |r| r.per_1000_km.phantom_braking_events),
    ];
    let top = families.iter().flat_map(|r| bars.iter().map(move |b| (b.2)(r))).fold(1.0f64, f64::max) * 1.15;
    let n = families.len().max(1);
    png(path, (1200, 600), |root| -> Drawn {
        let mut chart = ChartBuilder::on(root)
            .caption("eval sweep: events per 1,000 km, by family", ("sans-serif", 22))
            .margin(12)
            .x_label_area_size(70)
            .y_label_area_size(60)
            .build_cartesian_2d(0.0..n as f64, 0.0..top)?;
        let label = |x: &f64| {
            let i = x.floor() as usize;
            if (x - i as f64 - 0.5).abs() < 1e-6 {
                families.get(i).map_or(String::new(), |r| r.family.clone())
            } else {
                String::new()
            }
        };
        chart
            .configure_mesh()
            .disable_x_mesh()
            .x_labels(2 * n + 1)
            .x_label_formatter(&label)
            .x_label_style(("sans-serif", 13))
            .y_desc("events per 1,000 km")
            .draw()?;
        let width = 0.8 / bars.len() as f64;
        for (k, (name, color, value)) in bars.iter().enumerate() {
            let rects = families.iter().enumerate().map(|(i, r)| {
                let x0 = i as f64 + 0.1 + k as f64 * width;
                Rectangle::new([(x0, 0.0), (x0 + width * 0.9, value(r))], color.filled())
            });
            let color = *color;
            chart
                .draw_series(rects)?
                .label(*name)
                .legend(move |(x, y)| Rectangle::new([(x, y - 5), (x + 12, y + 5)], color.filled()));
        }
        draw_legend(&mut chart)
    })
}
