//! What a bench run reports: every suite's rows and the ratios, as JSON or as markdown tables.

use serde::Serialize;

use super::figures::Row;
use super::ratios::Ratio;
use super::{fleet, growth, nodes, scale, sim};
use slipstream_eval::fmt_opt;

#[derive(Debug, Clone, Serialize)]
pub struct BenchReport {
    pub command: String,
    pub rows: Vec<Row>,
    pub ratios: Vec<Ratio>,
    /// The simulator suite's figures (d).
    pub sim: Vec<sim::SimFigure>,
    /// Complete loops side by side (e), when asked for.
    pub scale: Vec<scale::ScaleRow>,
    /// Camera fan-out (f).
    pub fanout: Vec<growth::FanoutRow>,
    /// A router forwarding for several vehicles (g).
    pub router: Vec<growth::RouterRow>,
    /// A fleet through capped links (h), when asked for.
    pub fleet: Vec<fleet::FleetRow>,
    /// A controller of your own against slipstream-acc (i), when asked for.
    pub nodes: Vec<nodes::NodesRow>,
}

/// The report as markdown tables: one per suite, then the ratios.
pub fn markdown(report: &BenchReport) -> String {
    let mut s = String::new();
    let mut suite = "";
    for r in &report.rows {
        if r.suite != suite {
            suite = &r.suite;
            s.push_str(&format!("\n### {suite}\n\n| path | sent | received | lost | p50 us | p99 us | max us | frames/s | MB/s | shm frames | bg frames/s |\n|---|---|---|---|---|---|---|---|---|---|---|\n"));
        }
        s.push_str(&format!(
            "| {} | {:.0} | {:.0} | {:.0} | {} | {} | {} | {} | {} | {:.0} | {} |\n",
            r.path,
            r.sent,
            r.received,
            r.lost,
            fmt_opt(r.p50_us, 0),
            fmt_opt(r.p99_us, 0),
            fmt_opt(r.max_us, 0),
            fmt_opt(r.frames_per_s, 0),
            fmt_opt(r.mb_per_s, 0),
            r.shared_memory_frames,
            fmt_opt(r.background_frames_per_s, 1),
        ));
    }
    s.push_str(&hops_markdown(&report.rows));
    if !report.sim.is_empty() {
        s.push_str("\n### d. simulator (in process)\n\n| what | value | unit | aim |\n|---|---|---|---|\n");
        for f in &report.sim {
            s.push_str(&format!("| {} | {:.2} | {} | {} |\n", f.what, f.value, f.unit, f.aim));
        }
    }
    if !report.scale.is_empty() {
        s.push_str(&scale::markdown(&report.scale));
    }
    s.push_str(&growth::markdown(&report.fanout, &report.router));
    if !report.fleet.is_empty() {
        s.push_str(&fleet::markdown(&report.fleet));
    }
    if !report.nodes.is_empty() {
        s.push_str(&nodes::markdown(&report.nodes));
    }
    if !report.ratios.is_empty() {
        s.push_str("\n### Ratios (same run)\n\n| ratio | value | aim |\n|---|---|---|\n");
        for r in &report.ratios {
            let value = match (&r.value, &r.missing) {
                (Some(v), _) if *v < 0.1 => format!("{v:.4}"),
                (Some(v), _) => format!("{v:.2}"),
                (None, Some(m)) => format!("- ({m})"),
                (None, None) => "-".into(),
            };
            s.push_str(&format!("| {} | {} | {} |\n", r.what, value, r.aim));
        }
    }
    s
}

/// The frame rows read through a hand-off, hop by hop (p50): publish -> Zenoh's receive
/// callback (the link), callback -> the reader (the hand-off), and the whole way.
fn hops_markdown(rows: &[Row]) -> String {
    let hops: Vec<&Row> = rows.iter().filter(|r| r.handoff_p50_us.is_some()).collect();
    if hops.is_empty() {
        return String::new();
    }
    let mut s = String::from(
        "\n### Frame hops, p50 us\n\n| table | path | publish -> receive callback | callback -> reader | publish -> reader |\n|---|---|---|---|---|\n",
    );
    for r in hops {
        s.push_str(&format!(
            "| {} | {} | {} | {} | {} |\n",
            r.suite,
            r.path,
            fmt_opt(r.link_p50_us, 0),
            fmt_opt(r.handoff_p50_us, 0),
            fmt_opt(r.p50_us, 0)
        ));
    }
    s
}
