//! h. `slipstream bench fleet`: the deployment of the mission at fleet scale, on this machine.
//! Three hosts in network namespaces on one bridge, every host's link capped like a switch
//! port (`tc tbf`): the simulator PC runs N simulators (slipstream-sim, camera at 20 Hz, each
//! vehicle in a namespace of its own: car0, car1, ...), the client PC runs their detectors and
//! cruise controls, the router PC a Zenoh router between them. The client PC reads frames in
//! the encoding chosen (`--fleet-frames`: its topic config's camera.read, a link copy), so raw
//! frames stay on the simulator PC. Per cap and N: frames delivered / published, speed and
//! control lost, the loop's latency and the router's CPU. Needs root (namespaces).

use std::path::{Path, PathBuf};
use std::process::Stdio;
use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use serde::Serialize;

use super::fleet_watch::VehicleSeen;
use super::netns::Lan;
use crate::launch::{sibling_binary, Child};

/// The scenario every vehicle drives: a lead to follow the whole time.
const SCENARIO: &str = "steady-follow";
/// Address range of the LAN (a range the tests do not use).
const SUBNET: &str = "10.218.0";

/// One cap and number of vehicles.
#[derive(Debug, Clone, Serialize)]
pub struct FleetRow {
    pub cap_mbit_s: u32,
    pub vehicles: usize,
    /// What the client PC reads: the frames as published, or a link copy.
    pub frames: String,
    /// Front camera frames published (all simulators) and read by the detectors.
    pub frames_published: u64,
    pub frames_delivered: u64,
    pub frame_loss_percent: f64,
    /// vehicle/speed as the client PC received it, and lost on the way (sequence gaps).
    pub speed_received: u64,
    pub speed_lost: u64,
    /// vehicle/control as the simulators received it, and lost on the way.
    pub control_received: u64,
    pub control_lost: u64,
    /// Frame published -> command applied: the median vehicle's p50, the largest p99.
    pub loop_p50_ms: Option<f64>,
    pub loop_p99_ms: Option<f64>,
    /// The slowest simulator's real-time factor (below 1: this machine's CPU, not the link).
    pub rtf_min: f64,
    /// The router's CPU while the simulators ran, % of one core.
    pub router_cpu_percent: f64,
}

/// What `bench fleet` runs.
#[derive(Debug, Clone)]
pub struct FleetPlan {
    pub vehicles: Vec<usize>,
    pub caps_mbit_s: Vec<u32>,
    pub seconds: f64,
    /// camera.read on the client PC: "published", "raw", "lz4", "jpeg" or "png".
    pub frames: String,
    /// Zenoh settings (`--cfg KEY:VALUE`) for every node and the router.
    pub cfg: Vec<String>,
}

/// Every cap, every number of vehicles; progress on stderr.
pub fn run(plan: &FleetPlan) -> Result<Vec<FleetRow>> {
    let mut rows = Vec::new();
    for &cap in &plan.caps_mbit_s {
        for &n in &plan.vehicles {
            eprint!("[fleet] {n} vehicle(s) through {cap} Mbit/s links, frames {} ... ", plan.frames);
            let row = one(plan, cap, n).with_context(|| format!("{n} vehicles at {cap} Mbit/s"))?;
            eprintln!(
                "frames {}/{} ({:.1} % lost), speed lost {}, control lost {}, loop p50 {} ms, router {:.0} % CPU",
                row.frames_delivered,
                row.frames_published,
                row.frame_loss_percent,
                row.speed_lost,
                row.control_lost,
                row.loop_p50_ms.map_or("-".into(), |v| format!("{v:.1}")),
                row.router_cpu_percent
            );
            rows.push(row);
        }
    }
    Ok(rows)
}

/// The processes of one run, stopped (SIGINT, then SIGKILL) when dropped.
struct Hosts<'a> {
    lan: &'a Lan,
    logs: PathBuf,
    flags: Vec<String>,
    procs: Vec<Child>,
}

impl Hosts<'_> {
    /// Starts `program args` on `host` with the node flags; stdout to `<name>.out`, stderr to
    /// `<name>.log`.
    fn start(&mut self, host: &str, name: &str, program: &Path, args: &[String]) -> Result<usize> {
        let mut cmd = self.lan.command(host, program);
        cmd.args(args).args(&self.flags).env("RUST_LOG", "warn");
        cmd.stdout(std::fs::File::create(self.logs.join(format!("{name}.out")))?);
        cmd.stderr(std::fs::File::create(self.logs.join(format!("{name}.log")))?);
        cmd.stdin(Stdio::null());
        self.procs.push(Child::spawn(name, &mut cmd)?);
        Ok(self.procs.len() - 1)
    }

    fn output<T: serde::de::DeserializeOwned>(&self, name: &str) -> Result<T> {
        let path = self.logs.join(format!("{name}.out"));
        let text = std::fs::read_to_string(&path).with_context(|| format!("read {}", path.display()))?;
        serde_json::from_str(&text).with_context(|| format!("{name}: no report (see {})", path.display()))
    }
}

fn one(plan: &FleetPlan, cap: u32, n: usize) -> Result<FleetRow> {
    let tag = format!("sf{}", std::process::id() % 100_000);
    let lan = Lan::create(&tag, &["rt", "sim", "ctl"], SUBNET)?;
    for host in ["rt", "sim", "ctl"] {
        lan.cap(host, cap)?;
    }
    let logs = std::env::temp_dir().join(format!("slipstream-bench-fleet-{}/{cap}-{n}", std::process::id()));
    std::fs::create_dir_all(&logs)?;
    let remote = logs.join("client-pc.json5");
    std::fs::write(&remote, format!("{{ camera: {{ read: \"{}\" }} }}", plan.frames))?;
    let router_ep = format!("tcp/{}:7447", lan.addr("rt"));
    let flags = ["-m", "client", "-e", &router_ep, "--cfg", "transport/shared_memory/enabled:false"];
    let mut flags: Vec<String> = flags.map(String::from).to_vec();
    flags.extend(plan.cfg.iter().flat_map(|c| ["--cfg".to_string(), c.clone()]));
    let mut hosts = Hosts { lan: &lan, logs: logs.clone(), flags, procs: Vec::new() };
    let exe = std::env::current_exe()?;
    let router = hosts.start("rt", "router", &exe, &["router".into()])?;
    let (sim, detect, acc) = (sibling_binary("slipstream-sim")?, sibling_binary("slipstream-detect")?, sibling_binary("slipstream-acc")?);
    let topics = remote.display().to_string();
    for i in 0..n {
        let ns = format!("car{i}");
        hosts.start("ctl", &format!("acc{i}"), &acc, &s(&["--perception", "camera", "-n", &ns]))?;
        hosts.start("ctl", &format!("detect{i}"), &detect, &s(&["--json", "-n", &ns, "-t", &topics]))?;
    }
    let watch = hosts.start("ctl", "watch", &exe, &s(&["bench-fleet-watch", "--vehicles", &n.to_string()]))?;
    std::thread::sleep(Duration::from_millis(1500));
    let cpu0 = super::process_cpu_s(hosts.procs[router].pid()).unwrap_or(0.0);
    let started = Instant::now();
    let secs = format!("{}", plan.seconds);
    let sims: Vec<usize> = (0..n)
        .map(|i| hosts.start("sim", &format!("sim{i}"), &sim, &s(&["--scenario", SCENARIO, "--duration", &secs, "--json", "-n", &format!("car{i}")])))
        .collect::<Result<_>>()?;
    let limit = Duration::from_secs_f64(plan.seconds * 3.0 + 60.0);
    for &i in &sims {
        let left = limit.saturating_sub(started.elapsed());
        anyhow::ensure!(hosts.procs[i].wait_for(left).is_some(), "{} did not end within {limit:?} (logs in {})", hosts.procs[i].name, logs.display());
    }
    let cpu = (super::process_cpu_s(hosts.procs[router].pid()).unwrap_or(0.0) - cpu0) / started.elapsed().as_secs_f64();
    for p in &mut hosts.procs {
        p.interrupt();
    }
    for p in &mut hosts.procs {
        p.stop(Duration::from_secs(10));
    }
    let _ = watch;
    let row = figures(plan, &hosts, cap, n, cpu)?;
    drop(hosts);
    let _ = std::fs::remove_dir_all(&logs);
    Ok(row)
}

fn s(args: &[&str]) -> Vec<String> {
    args.iter().map(|a| a.to_string()).collect()
}

/// The run's figures from the reports the processes printed.
fn figures(plan: &FleetPlan, hosts: &Hosts, cap: u32, n: usize, router_cpu: f64) -> Result<FleetRow> {
    let seen: Vec<VehicleSeen> = hosts.output("watch")?;
    let (mut published, mut delivered, mut control_received, mut control_lost, mut rtf_min) = (0, 0, 0, 0, f64::INFINITY);
    for i in 0..n {
        let sim: crate::sim::SimReport = hosts.output(&format!("sim{i}"))?;
        let det: crate::perception::node::DetectStats = hosts.output(&format!("detect{i}"))?;
        published += sim.frames;
        delivered += det.frames + det.skipped + det.unusable;
        control_received += sim.control_input.received;
        control_lost += sim.control_input.lost;
        rtf_min = rtf_min.min(sim.real_time_factor);
    }
    let mut p50s: Vec<f64> = seen.iter().filter_map(|v| v.loop_p50_ms).collect();
    p50s.sort_by(f64::total_cmp);
    Ok(FleetRow {
        cap_mbit_s: cap,
        vehicles: n,
        frames: plan.frames.clone(),
        frames_published: published,
        frames_delivered: delivered.min(published),
        frame_loss_percent: 100.0 * published.saturating_sub(delivered) as f64 / published.max(1) as f64,
        speed_received: seen.iter().map(|v| v.speed_received).sum(),
        speed_lost: seen.iter().map(|v| v.speed_lost).sum(),
        control_received,
        control_lost,
        loop_p50_ms: p50s.get(p50s.len() / 2).copied(),
        loop_p99_ms: seen.iter().filter_map(|v| v.loop_p99_ms).reduce(f64::max),
        rtf_min,
        router_cpu_percent: router_cpu * 100.0,
    })
}

/// The rows as a markdown table.
pub fn markdown(rows: &[FleetRow]) -> String {
    let mut s = String::from(
        "\n### h. a fleet through capped links (simulator PC -> router PC -> client PC)\n\n| link cap Mbit/s | vehicles | client reads | frames delivered / published | frames lost % | speed lost | control lost | loop p50 ms | loop p99 ms | slowest RTF | router CPU % of a core |\n|---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    let ms = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{v:.1}"));
    for r in rows {
        s.push_str(&format!(
            "| {} | {} | {} | {} / {} | {:.2} | {} of {} | {} of {} | {} | {} | {:.2} | {:.0} |\n",
            r.cap_mbit_s,
            r.vehicles,
            r.frames,
            r.frames_delivered,
            r.frames_published,
            r.frame_loss_percent,
            r.speed_lost,
            r.speed_received + r.speed_lost,
            r.control_lost,
            r.control_received + r.control_lost,
            ms(r.loop_p50_ms),
            ms(r.loop_p99_ms),
            r.rtf_min,
            r.router_cpu_percent
        ));
    }
    s
}
