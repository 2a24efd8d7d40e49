//! h. `slipstream bench fleet`: the deployment of the mission at fleet scale, on this machine.
//! Three hosts in network namespaces on one bridge, every host's link capped like a switch
//! port (`tc tbf`): the simulator PC runs N simulators (slipstream-sim, camera at 20 Hz, each
//! vehicle in a namespace of its own: car0, car1, ...), the client PC runs their detectors and
//! cruise controls, the router PC a Zenoh router between them. The client PC reads frames in
//! the encoding chosen (`--fleet-frames`: its topic config's camera.read, a link copy), so raw
//! frames stay on the simulator PC. Per cap and N: frames delivered / published, speed and
//! control lost, the loop's latency and the router's CPU. With `--fleet-routers 3`, a mesh of
//! three routers, a subnet each ([`Placement`]). Needs root (namespaces).

use std::path::{Path, PathBuf};
use std::process::Stdio;
use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use serde::Serialize;

use super::fleet_watch::VehicleSeen;
use super::netns::Lan;
use slipstream_launch::{sibling_binary, Child};

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
    /// The routers' CPU while the simulators ran, % of one core, all routers together.
    pub router_cpu_percent: f64,
    /// Each router: its CPU, peak memory and how many vehicles' messages it carries (a mesh:
    /// the router that serves none of a vehicle's nodes carries none of its data).
    pub routers: Vec<RouterLoad>,
}

/// One router of a run.
#[derive(Debug, Clone, Serialize)]
pub struct RouterLoad {
    pub cpu_percent: f64,
    pub peak_rss_mib: Option<f64>,
    /// Vehicles with a node connected to this router.
    pub serves: usize,
}

/// What `bench fleet` runs.
#[derive(Debug, Clone)]
pub(crate) struct FleetPlan {
    pub vehicles: Vec<usize>,
    pub caps_mbit_s: Vec<u32>,
    pub seconds: f64,
    /// camera.read on the client PC: "published", "raw", "lz4", "jpeg" or "png".
    pub frames: String,
    /// 1: one router; 3: a mesh of three, a subnet each (see [`Placement`]).
    pub routers: usize,
    /// Zenoh settings (`--cfg KEY:VALUE`) for every node and the router.
    pub cfg: Vec<String>,
}

/// Every cap, every number of vehicles; progress on stderr.
pub(crate) fn run(plan: &FleetPlan) -> Result<Vec<FleetRow>> {
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
    /// Starts `program args` on `host` with the common flags and `-e endpoint`; stdout to
    /// `<name>.out`, stderr to `<name>.log`.
    fn start(
        &mut self,
        host: &str,
        name: &str,
        program: &Path,
        args: &[String],
        endpoint: Option<&str>,
    ) -> Result<usize> {
        let mut cmd = self.lan.command(host, program);
        cmd.args(args).args(&self.flags).env("RUST_LOG", "warn");
        if let Some(ep) = endpoint {
            cmd.args(["-e", ep]);
        }
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

    fn cpu_s(&self, i: usize) -> f64 {
        super::process_cpu_s(self.procs[i].pid()).unwrap_or(0.0)
    }
}

/// Where everything runs: one router and three hosts on one subnet, or a mesh of three
/// routers, each with a subnet of its own (its simulator PC and client PC) and a leg on a
/// backbone subnet the routers share. In the mesh, vehicle i's simulator sits on subnet
/// i % 3 and its detector and ACC on the next subnet: its messages cross two routers, and the
/// third does not serve it.
struct Placement {
    lan: Lan,
    /// Router host, the endpoints it dials (the routers before it).
    routers: Vec<(String, Vec<String>)>,
    /// Subnet k's address prefix: router k, simulator PC k and client PC k are on it.
    prefixes: Vec<String>,
    subnets: usize,
}

const MESH_BACKBONE: &str = "10.219.10";

/// With `subnets` subnets, vehicle i's simulator is on subnet i % subnets and its detector and
/// ACC on the next one (the same one when there is one subnet).
fn sides(i: usize, subnets: usize) -> (usize, usize) {
    let k = i % subnets;
    (k, (k + 1) % subnets)
}

impl Placement {
    fn build(tag: &str, routers: usize) -> Result<Placement> {
        if routers == 1 {
            let lan = Lan::create(tag, &["r0", "sim0", "ctl0"], SUBNET)?;
            let prefixes = vec![SUBNET.to_string()];
            return Ok(Placement { lan, routers: vec![("r0".into(), Vec::new())], prefixes, subnets: 1 });
        }
        let names: Vec<[String; 3]> =
            (0..routers).map(|k| [format!("r{k}"), format!("sim{k}"), format!("ctl{k}")]).collect();
        let prefixes: Vec<String> = (0..routers).map(|k| format!("10.219.{}", k + 1)).collect();
        let roles: Vec<Vec<&str>> = names.iter().map(|n| n.iter().map(String::as_str).collect()).collect();
        let backbone: Vec<&str> = names.iter().map(|n| n[0].as_str()).collect();
        let mut layout: Vec<(&str, &[&str])> =
            prefixes.iter().map(String::as_str).zip(roles.iter().map(Vec::as_slice)).collect();
        layout.push((MESH_BACKBONE, &backbone));
        let lan = Lan::create_subnets(tag, &layout)?;
        let routers = (0..routers)
            .map(|k| {
                let dials =
                    (0..k).map(|j| format!("tcp/{}:7447", lan.addr_on(&format!("r{j}"), MESH_BACKBONE))).collect();
                (format!("r{k}"), dials)
            })
            .collect();
        let subnets = prefixes.len();
        Ok(Placement { lan, routers, prefixes, subnets })
    }

    /// Subnet of vehicle i's simulator, and of its detector and ACC.
    fn sides(&self, i: usize) -> (usize, usize) {
        sides(i, self.subnets)
    }

    /// The endpoint of subnet k's router, as its hosts dial it.
    fn router_ep(&self, k: usize) -> String {
        format!("tcp/{}:7447", self.lan.addr_on(&format!("r{k}"), &self.prefixes[k]))
    }
}

fn one(plan: &FleetPlan, cap: u32, n: usize) -> Result<FleetRow> {
    let tag = format!("sf{}", std::process::id() % 100_000);
    let place = Placement::build(&tag, plan.routers)?;
    for k in 0..place.subnets {
        for host in [format!("r{k}"), format!("sim{k}"), format!("ctl{k}")] {
            place.lan.cap(&host, cap)?;
        }
    }
    let logs = std::env::temp_dir().join(format!("slipstream-bench-fleet-{}/{cap}-{n}", std::process::id()));
    std::fs::create_dir_all(&logs)?;
    let remote = logs.join("client-pc.json5");
    std::fs::write(&remote, format!("{{ camera: {{ read: \"{}\" }} }}", plan.frames))?;
    let mut flags = s(&["-m", "client", "--cfg", "transport/shared_memory/enabled:false"]);
    flags.extend(plan.cfg.iter().flat_map(|c| ["--cfg".to_string(), c.clone()]));
    let mut hosts = Hosts { lan: &place.lan, logs: logs.clone(), flags, procs: Vec::new() };
    let run = start_all(plan, &place, &mut hosts, &remote, n)?;
    let limit = Duration::from_secs_f64(plan.seconds * 3.0 + 60.0);
    for &i in &run.sims {
        let left = limit.saturating_sub(run.started.elapsed());
        let ended = hosts.procs[i].wait_for(left).is_some();
        anyhow::ensure!(ended, "{} did not end within {limit:?} (logs in {})", hosts.procs[i].name, logs.display());
    }
    let wall_s = run.started.elapsed().as_secs_f64();
    let routers: Vec<RouterLoad> = run
        .routers
        .iter()
        .zip(&run.cpu0)
        .enumerate()
        .map(|(k, (&i, &cpu0))| RouterLoad {
            cpu_percent: (hosts.cpu_s(i) - cpu0) / wall_s * 100.0,
            peak_rss_mib: super::process_peak_rss_mib(hosts.procs[i].pid()),
            serves: (0..n).filter(|&v| [place.sides(v).0, place.sides(v).1].contains(&k)).count(),
        })
        .collect();
    for p in &mut hosts.procs {
        p.interrupt();
    }
    for p in &mut hosts.procs {
        p.stop(Duration::from_secs(10));
    }
    let row = figures(plan, &hosts, cap, n, routers, place.subnets)?;
    drop(hosts);
    let _ = std::fs::remove_dir_all(&logs);
    Ok(row)
}

/// The processes of a run once started: routers, clients, watchers, then the simulators.
struct Started {
    routers: Vec<usize>,
    cpu0: Vec<f64>,
    sims: Vec<usize>,
    started: Instant,
}

fn start_all(plan: &FleetPlan, place: &Placement, hosts: &mut Hosts, remote: &Path, n: usize) -> Result<Started> {
    let exe = std::env::current_exe()?;
    let mut routers = Vec::new();
    for (k, (host, dials)) in place.routers.iter().enumerate() {
        let mut args = vec!["router".to_string()];
        args.extend(dials.iter().flat_map(|d| ["-e".to_string(), d.clone()]));
        routers.push(hosts.start(host, &format!("router{k}"), &exe, &args, None)?);
    }
    let (sim, detect, acc) =
        (sibling_binary("slipstream-sim")?, sibling_binary("slipstream-detect")?, sibling_binary("slipstream-acc")?);
    let topics = remote.display().to_string();
    for i in 0..n {
        let (ns, (_, c)) = (format!("car{i}"), place.sides(i));
        let (host, ep) = (format!("ctl{c}"), place.router_ep(c));
        hosts.start(&host, &format!("acc{i}"), &acc, &s(&["--perception", "camera", "-n", &ns]), Some(&ep))?;
        hosts.start(&host, &format!("detect{i}"), &detect, &s(&["--json", "-n", &ns, "-t", &topics]), Some(&ep))?;
    }
    for c in 0..place.subnets {
        let ids: Vec<String> = (0..n).filter(|&i| place.sides(i).1 == c).map(|i| i.to_string()).collect();
        if !ids.is_empty() {
            let args = s(&["bench-fleet-watch", "--ids", &ids.join(",")]);
            hosts.start(&format!("ctl{c}"), &format!("watch{c}"), &exe, &args, Some(&place.router_ep(c)))?;
        }
    }
    std::thread::sleep(Duration::from_millis(1500));
    let cpu0 = routers.iter().map(|&i| hosts.cpu_s(i)).collect();
    let started = Instant::now();
    let secs = format!("{}", plan.seconds);
    let mut sims = Vec::new();
    for i in 0..n {
        let (k, _) = place.sides(i);
        let args = s(&["--scenario", SCENARIO, "--duration", &secs, "--json", "-n", &format!("car{i}")]);
        sims.push(hosts.start(&format!("sim{k}"), &format!("sim{i}"), &sim, &args, Some(&place.router_ep(k)))?);
    }
    Ok(Started { routers, cpu0, sims, started })
}

fn s(args: &[&str]) -> Vec<String> {
    args.iter().map(|a| a.to_string()).collect()
}

/// The run's figures from the reports the processes printed.
fn figures(
    plan: &FleetPlan,
    hosts: &Hosts,
    cap: u32,
    n: usize,
    routers: Vec<RouterLoad>,
    subnets: usize,
) -> Result<FleetRow> {
    let mut seen: Vec<VehicleSeen> = Vec::new();
    for c in 0..subnets {
        if hosts.logs.join(format!("watch{c}.out")).is_file() {
            seen.extend(hosts.output::<Vec<VehicleSeen>>(&format!("watch{c}"))?);
        }
    }
    let (mut published, mut delivered, mut control_received, mut control_lost, mut rtf_min) =
        (0, 0, 0, 0, f64::INFINITY);
    for i in 0..n {
        let sim: slipstream_sim::SimReport = hosts.output(&format!("sim{i}"))?;
        let det: slipstream_perception::node::DetectStats = hosts.output(&format!("detect{i}"))?;
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
        router_cpu_percent: routers.iter().map(|r| r.cpu_percent).sum(),
        routers,
    })
}

/// The rows as a markdown table.
pub(crate) fn markdown(rows: &[FleetRow]) -> String {
    let mut s = String::from(
        "\n### h. a fleet through capped links (simulator PC -> router(s) -> client PC)\n\n| link cap Mbit/s | vehicles | client reads | frames delivered / published | frames lost % | speed lost | control lost | loop p50 ms | loop p99 ms | slowest RTF | router CPU % of a core | each router: CPU %, peak MiB, vehicles served |\n|---|---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    let ms = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{v:.1}"));
    for r in rows {
        s.push_str(&format!(
            "| {} | {} | {} | {} / {} | {:.2} | {} of {} | {} of {} | {} | {} | {:.2} | {:.0} | {} |\n",
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
            r.router_cpu_percent,
            r.routers
                .iter()
                .map(|l| format!("{:.1} %, {}, {}", l.cpu_percent, ms(l.peak_rss_mib), l.serves))
                .collect::<Vec<_>>()
                .join("; ")
        ));
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn in_a_mesh_every_vehicle_crosses_two_routers_and_one_router_skips_it() {
        for i in 0..9 {
            let (a, b) = sides(i, 3);
            assert_ne!(a, b, "vehicle {i} crosses the backbone");
        }
        assert_eq!([sides(0, 3), sides(1, 3), sides(2, 3), sides(3, 3)], [(0, 1), (1, 2), (2, 0), (0, 1)]);
        assert_eq!(sides(5, 1), (0, 0));
    }

    #[test]
    fn the_table_shows_each_router_and_what_it_serves() {
        let load = |cpu, serves| RouterLoad { cpu_percent: cpu, peak_rss_mib: Some(18.4), serves };
        let row = FleetRow {
            cap_mbit_s: 1000,
            vehicles: 1,
            frames: "lz4".into(),
            frames_published: 200,
            frames_delivered: 198,
            frame_loss_percent: 1.0,
            speed_received: 850,
            speed_lost: 2,
            control_received: 999,
            control_lost: 1,
            loop_p50_ms: Some(3.6),
            loop_p99_ms: None,
            rtf_min: 1.0,
            router_cpu_percent: 4.1,
            routers: vec![load(1.9, 1), load(2.2, 1), load(0.0, 0)],
        };
        let md = markdown(&[row]);
        assert!(md.contains("| 1000 | 1 | lz4 | 198 / 200 | 1.00 | 2 of 852 | 1 of 1000 | 3.6 | - |"), "{md}");
        assert!(md.contains("1.9 %, 18.4, 1; 2.2 %, 18.4, 1; 0.0 %, 18.4, 0 |"), "{md}");
    }
}
