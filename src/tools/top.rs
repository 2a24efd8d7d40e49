//! `slipstream top`: every key seen in the namespace, with its rate, bandwidth, latency from
//! the header stamps, losses (sequence gaps), malformed payloads and the age of its last
//! message; the nodes alive; the simulator's clock and real-time factor. A live table on a
//! terminal, one JSON object per refresh otherwise (or with --json). The namespace is the
//! bus's (-n); the default one is the root loop's topics, not the other namespaces beneath it
//! (`--all-namespaces` watches the whole bus).

use std::io::{IsTerminal, Write};
use std::time::{Duration, Instant};

use anyhow::Result;

use crate::bus::Bus;
use crate::eval::fmt_opt;
pub use crate::observe::watch::{KeyRow, SimView, TopView, Watcher};

#[derive(Debug, Clone, clap::Args)]
pub struct TopArgs {
    /// Print one JSON object per refresh instead of the live table (the default when stdout is
    /// not a terminal)
    #[arg(long)]
    pub json: bool,
    /// Seconds between refreshes
    #[arg(long, default_value_t = 1.0, value_parser = positive)]
    pub interval: f64,
    /// Stop after this many seconds [default: until Ctrl-C]
    #[arg(long, value_parser = positive)]
    pub duration: Option<f64>,
    /// Every key of every namespace (other loops, anyone's keys), not only this namespace's
    /// loop; in the default namespace `top` shows the root loop's topics and nodes alone
    #[arg(long)]
    pub all_namespaces: bool,
}

pub(crate) fn positive(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(v) if v.is_finite() && v > 0.0 => Ok(v),
        _ => Err(format!("`{s}` is not a number of seconds > 0")),
    }
}

/// The live table.
pub fn render(view: &TopView) -> String {
    let mut s = format!(
        "slipstream top   namespace {}   nodes: {}\n",
        if view.namespace.is_empty() { "(none)" } else { &view.namespace },
        if view.nodes.is_empty() { "(none)".to_string() } else { view.nodes.join(", ") }
    );
    match &view.sim {
        Some(c) => s.push_str(&format!(
            "sim{}: {:.1} s simulated, step {}, real-time factor {:.2} ({})\n\n",
            if c.replayed { " (a replay, not live)" } else { "" },
            c.sim_time_s,
            c.step,
            c.real_time_factor,
            c.mode
        )),
        None => s.push_str("sim: no sim/clock seen\n\n"),
    }
    s.push_str(&format!(
        "{:<28} {:<8} {:>8} {:>9} {:>11} {:>9} {:>9} {:>6} {:>5} {:>7}\n",
        "KEY", "FROM", "MSGS", "RATE Hz", "BANDWIDTH", "P50 us", "P99 us", "LOST", "BAD", "AGE s"
    ));
    for r in &view.keys {
        let st = &r.stats;
        s.push_str(&format!(
            "{:<28} {:<8} {:>8} {:>9.1} {:>11} {:>9} {:>9} {:>6} {:>5} {:>7}\n",
            r.key,
            r.from.as_deref().unwrap_or("-"),
            st.received,
            st.rate_hz,
            bandwidth(st.bandwidth_bps),
            fmt_opt(st.latency_p50_us, 0),
            fmt_opt(st.latency_p99_us, 0),
            st.lost,
            st.decode_errors,
            fmt_opt(st.age_s, 1),
        ));
    }
    if !view.node_inputs.is_empty() {
        s.push_str(&format!(
            "\ninjected faults at the nodes' inputs (--faults)\n{:<14} {:<20} {:>8} {:>13} {:>9} {:>9} {:>10}\n",
            "NODE", "INPUT", "ARRIVED", "LOST ON WAY", "DROPPED", "DELAYED", "DUPLICATED"
        ));
        for r in &view.node_inputs {
            let st = &r.stats;
            s.push_str(&format!(
                "{:<14} {:<20} {:>8} {:>13} {:>9} {:>9} {:>10}\n",
                r.node,
                st.topic,
                st.received,
                st.lost,
                st.injected_dropped,
                st.injected_delayed,
                st.injected_duplicated
            ));
        }
    }
    if view.keys.is_empty() {
        s.push_str("(nothing seen yet: is anything running in this namespace, and connected? see `slipstream info`)\n");
    }
    s
}

fn bandwidth(bps: f64) -> String {
    if bps >= 1e6 {
        format!("{:.1} Mb/s", bps / 1e6)
    } else {
        format!("{:.1} kb/s", bps / 1e3)
    }
}

/// Runs until Ctrl-C or `--duration`.
pub async fn run(bus: &Bus, args: &TopArgs) -> Result<()> {
    let topics = bus.topics();
    let keys = if args.all_namespaces { topics.every_namespace_key() } else { topics.every_key() };
    let watcher = Watcher::start(bus, &keys).await?;
    let json = args.json || !std::io::stdout().is_terminal();
    let deadline = args.duration.map(|d| Instant::now() + Duration::from_secs_f64(d));
    let mut tick = tokio::time::interval(Duration::from_secs_f64(args.interval));
    tick.tick().await;
    let ctrl_c = crate::cli::stop_requested();
    tokio::pin!(ctrl_c);
    let mut out = std::io::stdout();
    loop {
        tokio::select! {
            _ = &mut ctrl_c => break,
            _ = tick.tick() => {}
        }
        let view = watcher.view();
        if json {
            writeln!(out, "{}", serde_json::to_string(&view)?)?;
        } else {
            // A screen of its own on the terminal: cleared, then drawn.
            console::Term::stdout().clear_screen()?;
            writeln!(out, "{}(Ctrl-C to quit)", render(&view))?;
        }
        out.flush()?;
        if deadline.is_some_and(|d| Instant::now() >= d) {
            break;
        }
    }
    Ok(())
}

/// `slipstream top`: watches until Ctrl-C (or its --duration).
pub fn command(args: &TopArgs, connect: &crate::ConnectArgs) -> Result<std::process::ExitCode> {
    crate::cli::on_bus(connect, &crate::cli::own_name("top"), |bus| async move { run(&bus, args).await })?;
    Ok(std::process::ExitCode::SUCCESS)
}
