//! `slipstream top`: every key seen in the namespace, with its rate, bandwidth, latency from
//! the header stamps, losses (sequence gaps), malformed payloads and the age of its last
//! message; the nodes alive; the simulator's clock and real-time factor. A live table on a
//! terminal, one JSON object per refresh otherwise (or with --json).

use std::collections::BTreeMap;
use std::io::{IsTerminal, Write};
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::Result;
use parking_lot::Mutex;
use serde::Serialize;

use crate::bus::{Bus, StatsSnapshot, TopicStats};
use crate::eval::fmt_opt;
use crate::launch::NodeInput;
use crate::msg::{self, MessageKind};

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
}

pub(crate) fn positive(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(v) if v.is_finite() && v > 0.0 => Ok(v),
        _ => Err(format!("`{s}` is not a number of seconds > 0")),
    }
}

/// One key as one publisher sends it.
#[derive(Debug, Clone, Serialize)]
pub struct KeyRow {
    pub key: String,
    /// The topic the key is mapped to, when it is one of slipstream's.
    pub topic: Option<&'static str>,
    /// The publishing node (the sample's attachment), when it names itself.
    pub from: Option<String>,
    /// The message type the payloads say they hold.
    pub kind: Option<&'static str>,
    #[serde(flatten)]
    pub stats: StatsSnapshot,
}

/// The simulator's clock as sim/clock last said.
#[derive(Debug, Clone, Serialize)]
pub struct SimView {
    pub sim_time_s: f64,
    pub step: u64,
    pub real_time_factor: f64,
    pub mode: String,
}

/// One refresh.
#[derive(Debug, Clone, Serialize)]
pub struct TopView {
    pub elapsed_s: f64,
    pub namespace: String,
    pub nodes: Vec<String>,
    pub sim: Option<SimView>,
    pub keys: Vec<KeyRow>,
    /// The inputs of nodes that inject faults (`--faults`), as they report them: injected
    /// drops, delays and duplicates apart from what the network lost.
    pub node_inputs: Vec<NodeInput>,
}

/// Each key seen (with the publisher's encoding, for keys that are not the loop's): its
/// statistics and the message kind it carries.
type KeyStats = BTreeMap<(String, Option<String>), (Arc<TopicStats>, Option<MessageKind>)>;

#[derive(Default)]
struct Seen {
    keys: KeyStats,
    sim: Option<SimView>,
    node_inputs: BTreeMap<String, Vec<StatsSnapshot>>,
}

/// Records every sample of the namespace.
pub struct Watcher {
    seen: Arc<Mutex<Seen>>,
    _subs: Vec<crate::bus::Declared>,
    nodes: crate::bus::NodesWatch,
    started: Instant,
}

impl Watcher {
    /// Watches `selectors` (`TopicMap::every_key` for `top`, `TopicMap::loop_keys` for `up`).
    pub async fn start(bus: &Bus, selectors: &[zenoh::key_expr::OwnedKeyExpr]) -> Result<Watcher> {
        let seen = Arc::new(Mutex::new(Seen::default()));
        let topics = bus.topics();
        let mut subs = Vec::new();
        for sel in selectors.iter().cloned() {
            let seen = seen.clone();
            let map = topics.clone();
            subs.push(bus.subscribe_samples(sel, false, move |sample| record(&seen, &map, &sample)).await?);
        }
        Ok(Watcher { seen, _subs: subs, nodes: bus.watch_nodes().await?, started: Instant::now() })
    }

    pub fn view(&self, bus: &Bus) -> TopView {
        let seen = self.seen.lock();
        let topics = bus.topics();
        let keys = seen
            .keys
            .iter()
            .map(|((key, from), (stats, kind))| KeyRow {
                key: key.clone(),
                topic: zenoh::key_expr::keyexpr::new(key.as_str())
                    .ok()
                    .and_then(|k| topics.topic_of(k))
                    .map(|t| t.name()),
                from: from.clone(),
                kind: kind.map(|k| k.name()),
                // The row names its key and topic: the snapshot's name (the key) would repeat
                // the field `topic` in JSON with another meaning.
                stats: StatsSnapshot { topic: String::new(), ..stats.snapshot() },
            })
            .collect();
        TopView {
            elapsed_s: self.started.elapsed().as_secs_f64(),
            namespace: topics.namespace().to_string(),
            nodes: self.nodes.names(),
            sim: seen.sim.clone(),
            keys,
            node_inputs: seen
                .node_inputs
                .iter()
                .flat_map(|(node, v)| v.iter().map(|stats| NodeInput { node: node.clone(), stats: stats.clone() }))
                .collect(),
        }
    }
}

fn record(seen: &Mutex<Seen>, topics: &crate::TopicMap, sample: &zenoh::sample::Sample) {
    let key = sample.key_expr().as_str().to_string();
    if let Some(node) = topics.node_of_inputs_key(&key) {
        // A node's inputs report (JSON), not a message of the loop.
        #[derive(serde::Deserialize)]
        struct Report {
            inputs: Vec<StatsSnapshot>,
        }
        if let Ok(r) = serde_json::from_slice::<Report>(&sample.payload().to_bytes()) {
            seen.lock().node_inputs.insert(node, r.inputs);
        }
        return;
    }
    if crate::bus::is_foreign(sample, topics) {
        return;
    }
    let from = sample.attachment().and_then(|a| a.try_to_string().ok()).map(|s| s.into_owned());
    let payload = sample.payload().to_bytes();
    // On a topic's key, a message of another type is as wrong as bytes that do not decode.
    let expected = topics.topic_of(sample.key_expr()).map(|t| t.kind());
    let decoded = msg::decode_json(&payload).and_then(|d| match expected {
        Some(kind) if kind != d.0 => Err(msg::DecodeError::WrongKind { expected: kind.name(), found: d.0.name() }),
        _ => Ok(d),
    });
    let mut seen = seen.lock();
    let entry = seen.keys.entry((key.clone(), from)).or_insert_with(|| (Arc::new(TopicStats::new(key.clone())), None));
    match decoded {
        Ok((kind, header, body)) => {
            entry.0.on_message(&header, payload.len(), msg::wall_clock_ns());
            entry.1 = Some(kind);
            if kind == MessageKind::SimClock {
                seen.sim = Some(SimView {
                    sim_time_s: header.stamp_sim_ns as f64 / 1e9,
                    step: body["step"].as_u64().unwrap_or(0),
                    real_time_factor: body["real_time_factor"].as_f64().unwrap_or(0.0),
                    mode: body["mode"].as_str().unwrap_or("?").to_string(),
                });
            }
        }
        Err(e) => {
            entry.1 = msg::peek_kind(&payload).ok();
            entry.0.on_decode_error(&e);
        }
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
            "sim: {:.1} s simulated, step {}, real-time factor {:.2} ({})\n\n",
            c.sim_time_s, c.step, c.real_time_factor, c.mode
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
    let watcher = Watcher::start(bus, &bus.topics().every_key()).await?;
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
        let view = watcher.view(bus);
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
