//! `slipstream bench`: the bus against raw Zenoh, UDP and TCP, two processes on loopback, in
//! one run so every ratio compares figures taken on the same machine at the same time.
//!
//! Each case starts a receiver and a sender as child processes (`slipstream bench-peer`),
//! so a case can give both its own environment (ZENOH_RUNTIME) and nothing is shared but the
//! loopback interface. The receiver timestamps arrival against the publish time in the
//! message: one-way latency on one host's clock.

pub mod fleet;
pub mod fleet_watch;
pub mod growth;
mod netns;
mod peer;
mod plot;
pub mod scale;
pub mod sim;
mod spec;

use std::io::{BufRead, BufReader, Write};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use serde::Serialize;

use crate::eval::fmt_opt;

pub use peer::{run_receiver, run_sender};
pub use spec::{Background, CaseSpec, Payload, RecvReport, SendReport, TcpBuffer, Transport};

/// ZENOH_RUNTIME value that gives Zenoh's own thread layout (a pool per role) instead of
/// slipstream's default handover layout (`crate::cli::ZENOH_RUNTIME_DEFAULT`).
pub const ZENOH_OWN_RUNTIME: &str = "()";

#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Suite {
    /// a. speed-size messages at 100 Hz: one-way latency per path
    Speed,
    /// b. 640x480 and 1280x720 RGB frames: frames/s, MB/s, one-way latency
    Frames,
    /// c. speed latency and losses while frames load the link
    Contention,
    /// d. the simulator: physics steps/s, render time per frame, fast-mode real-time factor
    Sim,
    /// e. complete loops side by side in realtime (1, 2, 4, 8): real-time factor, loop
    /// latency, CPU per loop; only when named (it loads the whole machine for minutes)
    Scale,
    /// f. camera fan-out: 640x480 frames to 1, 2, 4, 8 subscribers, in shared memory and
    /// through a router: frames/s and latency per subscriber
    Fanout,
    /// g. a router forwarding speed + control for 1-64 vehicles (--vehicles): messages/s,
    /// added latency, the router's CPU and memory
    Router,
    /// h. a fleet through capped links: N simulators on one host, their detectors and ACCs on
    /// another, a router between, every link capped (network namespaces, tc tbf; root);
    /// frames delivered, speed and control lost, loop latency, router CPU; only when named
    Fleet,
}

#[derive(Debug, Clone, clap::Args)]
pub struct BenchArgs {
    /// Which suites to run [default: all]
    #[arg(value_enum)]
    pub suites: Vec<Suite>,
    /// Runs per case; figures are medians over runs
    #[arg(long, default_value_t = 3)]
    pub repeat: usize,
    /// Few messages and one run: checks that every path works (a smoke test, not figures)
    #[arg(long)]
    pub quick: bool,
    /// Print the results as JSON on stdout instead of the table
    #[arg(long)]
    pub json: bool,
    /// Also write the table (markdown) to this file
    #[arg(long, value_name = "FILE")]
    pub markdown: Option<std::path::PathBuf>,
    /// scale: how many complete loops side by side, in turn
    #[arg(long, value_delimiter = ',', default_value = "1,2,4,8,12,16")]
    pub loops: Vec<usize>,
    /// scale: simulated (= wall) seconds each batch of loops runs
    #[arg(long, default_value_t = 20.0)]
    pub scale_seconds: f64,
    /// fanout: how many subscribers, in turn
    #[arg(long, value_delimiter = ',', default_value = "1,2,4,8")]
    pub subscribers: Vec<usize>,
    /// router: how many vehicles, in turn (1 to 64)
    #[arg(long, value_delimiter = ',', default_value = "1,2,4,8,16")]
    pub vehicles: Vec<usize>,
    /// speed: also run the bus rows with the peers of another slipstream build, side by side
    /// with this one's, e.g. --with-build uring=/tmp/uring/release/slipstream (built with
    /// `cargo build --release --features uring`); repeatable
    #[arg(long, value_name = "LABEL=PATH")]
    pub with_build: Vec<String>,
    /// fleet: how many vehicles, in turn
    #[arg(long, value_delimiter = ',', default_value = "1,2,4,8")]
    pub fleet_vehicles: Vec<usize>,
    /// fleet: the links' caps in Mbit/s, in turn
    #[arg(long, value_delimiter = ',', default_value = "1000,100")]
    pub fleet_caps: Vec<u32>,
    /// fleet: seconds each batch of vehicles drives (realtime)
    #[arg(long, default_value_t = 20.0)]
    pub fleet_seconds: f64,
    /// fleet: what the client PC reads (its camera.read): a link copy (lz4, jpeg, png, raw)
    /// or "published"
    #[arg(long, default_value = "jpeg", value_parser = ["published", "raw", "lz4", "jpeg", "png"])]
    pub fleet_frames: String,
    /// fleet: 1 router, or a mesh of 3 (a subnet each, a backbone between them; vehicle i's
    /// simulator on subnet i % 3, its detector and ACC on the next)
    #[arg(long, default_value_t = 1, value_parser = clap::builder::TypedValueParser::map(
        clap::builder::PossibleValuesParser::new(["1", "3"]),
        |v: String| v.parse::<usize>().unwrap_or(1)
    ))]
    pub fleet_routers: usize,
    /// fleet: a Zenoh setting for every node and the router, e.g. --fleet-cfg
    /// transport/link/tx/queue/size/real_time:16 (KEY:VALUE as --cfg; repeatable)
    #[arg(long, value_name = "KEY:VALUE")]
    pub fleet_cfg: Vec<String>,
    /// Also draw how the cost grows (scale, fanout, router: whichever ran) into this PNG
    #[arg(long, value_name = "FILE")]
    pub plot: Option<std::path::PathBuf>,
}

/// One measured path in one suite, medians over runs.
#[derive(Debug, Clone, Serialize)]
pub struct Row {
    pub suite: String,
    pub path: String,
    pub runs: usize,
    pub sent: f64,
    pub received: f64,
    pub lost: f64,
    pub p50_us: Option<f64>,
    pub p99_us: Option<f64>,
    pub max_us: Option<f64>,
    pub frames_per_s: Option<f64>,
    pub mb_per_s: Option<f64>,
    pub shared_memory_frames: f64,
    pub background_frames_per_s: Option<f64>,
}

#[derive(Debug, Clone, Serialize)]
pub struct Ratio {
    pub what: String,
    pub value: f64,
    pub aim: String,
}

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
}

struct Case {
    suite: String,
    path: String,
    spec: CaseSpec,
}

fn speed_spec(transport: Transport, count: u64) -> CaseSpec {
    CaseSpec {
        transport,
        payload: Payload::Speed,
        count,
        rate_hz: Some(100.0),
        max_duration_s: count as f64 / 100.0 + 10.0,
        qos: true,
        shm: true,
        lowlatency: false,
        runtime: None,
        tcp_buffer: TcpBuffer::Default,
        unix_socket: false,
        background: None,
        via_router: false,
        namespace: None,
        control_echo: false,
        callback_reader: false,
        peer_exe: None,
        pin_cpu: None,
        subscribers: 1,
    }
}

/// Another build's binary, by label (`--with-build LABEL=PATH`).
struct OtherBuild {
    label: String,
    exe: String,
}

fn other_builds(args: &[String]) -> Result<Vec<OtherBuild>> {
    args.iter()
        .map(|a| {
            let (label, exe) = a
                .split_once('=')
                .with_context(|| format!("--with-build {a}: write LABEL=PATH, e.g. uring=/tmp/uring/release/slipstream"))?;
            anyhow::ensure!(
                std::path::Path::new(exe).is_file(),
                "--with-build {a}: no file at {exe} (build it, e.g. CARGO_TARGET_DIR=/tmp/uring cargo build --release --features uring)"
            );
            Ok(OtherBuild { label: label.to_string(), exe: exe.to_string() })
        })
        .collect()
}

/// Frames of `size` at `rate_hz` (a latency case: 60 frames) or as fast as the sender can
/// (throughput: up to 3 s), from one sender to one receiver.
fn frame_spec(
    transport: Transport,
    (width, height): (u32, u32),
    shm: bool,
    rate_hz: Option<f64>,
    quick: bool,
) -> CaseSpec {
    CaseSpec {
        payload: Payload::Frame { width, height },
        count: match (rate_hz, quick) {
            (Some(_), true) => 10,
            (Some(_), false) => 60,
            (None, true) => 200,
            (None, false) => 20_000,
        },
        rate_hz,
        max_duration_s: match (rate_hz, quick) {
            (Some(_), _) => 20.0,
            (None, true) => 1.0,
            (None, false) => 3.0,
        },
        shm,
        ..speed_spec(transport, 0)
    }
}

fn cases(suites: &[Suite], quick: bool, builds: &[OtherBuild]) -> Vec<Case> {
    let mut out = Vec::new();
    let speed_n = if quick { 50 } else { 500 };
    let mut push =
        |suite: &str, path: &str, spec: CaseSpec| out.push(Case { suite: suite.into(), path: path.into(), spec });

    if suites.contains(&Suite::Speed) {
        let s = "a. speed 100 Hz";
        if python_available() {
            push(s, "seed: Python UDP", speed_spec(Transport::SeedPythonUdp, speed_n));
        } else {
            eprintln!("note: no {PYTHON} here: the seed's Python UDP row is left out");
        }
        push(s, "raw UDP", speed_spec(Transport::Udp, speed_n));
        push(s, "raw TCP", speed_spec(Transport::Tcp, speed_n));
        push(s, "raw zenoh", speed_spec(Transport::Zenoh, speed_n));
        push(s, "bus", speed_spec(Transport::Bus, speed_n));
        let zenoh_rt = || Some(ZENOH_OWN_RUNTIME.to_string());
        push(
            s,
            "raw zenoh, zenoh's runtime",
            CaseSpec { runtime: zenoh_rt(), ..speed_spec(Transport::Zenoh, speed_n) },
        );
        push(s, "bus, zenoh's runtime", CaseSpec { runtime: zenoh_rt(), ..speed_spec(Transport::Bus, speed_n) });
        push(s, "bus, lowlatency transport", CaseSpec { lowlatency: true, ..speed_spec(Transport::Bus, speed_n) });
        push(s, "raw zenoh, unix socket", CaseSpec { unix_socket: true, ..speed_spec(Transport::Zenoh, speed_n) });
        push(s, "bus, unix socket", CaseSpec { unix_socket: true, ..speed_spec(Transport::Bus, speed_n) });
        // A lead for a real-time session of its own: Zenoh's low-latency transport (no
        // priorities, so not for frames) over the one-host link.
        push(
            s,
            "bus, lowlatency transport, unix socket",
            CaseSpec { lowlatency: true, unix_socket: true, ..speed_spec(Transport::Bus, speed_n) },
        );
        // Issue 17's other leads for the speed path. (Batching off, `transport/link/tx/queue/
        // batching/enabled: false`, is not a row: Zenoh 1.10 then closes the transport before
        // the peers match, "Unable to push non droppable network message".)
        push(
            s,
            "bus, kernel socket buffers",
            CaseSpec { tcp_buffer: TcpBuffer::Kernel, ..speed_spec(Transport::Bus, speed_n) },
        );
        push(s, "bus, both peers on one core", CaseSpec { pin_cpu: Some(0), ..speed_spec(Transport::Bus, speed_n) });
        for b in builds {
            let other = |spec: CaseSpec| CaseSpec { peer_exe: Some(b.exe.clone()), ..spec };
            push(s, &format!("bus, {}", b.label), other(speed_spec(Transport::Bus, speed_n)));
            push(
                s,
                &format!("bus, unix socket, {}", b.label),
                other(CaseSpec { unix_socket: true, ..speed_spec(Transport::Bus, speed_n) }),
            );
        }
    }
    if suites.contains(&Suite::Frames) {
        for (w, h) in [(640u32, 480u32), (1280, 720)] {
            let frame = |transport, shm, rate_hz: Option<f64>| frame_spec(transport, (w, h), shm, rate_hz, quick);
            for (phase, rate) in [("throughput", None), ("latency @20 Hz", Some(20.0))] {
                let s = format!("b. {w}x{h} RGB frames, {phase}");
                push(&s, "bus, shared memory", frame(Transport::Bus, true, rate));
                // The link `up` and `eval` give the loop's processes: the shared-memory
                // descriptor crosses a unix socket instead of TCP.
                push(
                    &s,
                    "bus, shared memory, unix socket",
                    CaseSpec { unix_socket: true, ..frame(Transport::Bus, true, rate) },
                );
                if rate.is_some() {
                    // The same, read in Zenoh's receive callback: what the latest-only
                    // reader's hand-off to the application's task adds.
                    push(
                        &s,
                        "bus, shared memory, unix socket, callback reader",
                        CaseSpec { unix_socket: true, callback_reader: true, ..frame(Transport::Bus, true, rate) },
                    );
                }
                push(&s, "bus, TCP (shm off)", frame(Transport::Bus, false, rate));
                push(&s, "raw zenoh, TCP (shm off)", frame(Transport::Zenoh, false, rate));
                push(&s, "raw zenoh, implicit shm", frame(Transport::Zenoh, true, rate));
                push(&s, "raw TCP", frame(Transport::Tcp, false, rate));
                if rate.is_none() {
                    let zrt = |spec: CaseSpec| CaseSpec { runtime: Some(ZENOH_OWN_RUNTIME.into()), ..spec };
                    push(&s, "bus, shared memory, zenoh's runtime", zrt(frame(Transport::Bus, true, rate)));
                    push(&s, "bus, TCP (shm off), zenoh's runtime", zrt(frame(Transport::Bus, false, rate)));
                }
            }
        }
    }
    if suites.contains(&Suite::Contention) {
        let n = if quick { 50 } else { 300 };
        let loaded = |rate: Option<f64>, qos: bool, shm: bool| CaseSpec {
            qos,
            shm,
            background: Some(Background { width: 640, height: 480, rate_hz: rate, nice: 0 }),
            ..speed_spec(Transport::Bus, n)
        };
        let s = "c. bus speed 100 Hz under 640x480 frames";
        push(s, "unloaded", speed_spec(Transport::Bus, n));
        push(s, "frames 30 Hz, QoS, TCP", loaded(Some(30.0), true, false));
        push(s, "frames 30 Hz, QoS off, TCP", loaded(Some(30.0), false, false));
        push(s, "frames saturating, QoS, TCP", loaded(None, true, false));
        push(s, "frames saturating, QoS off, TCP", loaded(None, false, false));
        push(s, "frames saturating, QoS, shm", loaded(None, true, true));
        push(s, "frames saturating, QoS, shm, frame thread at nice 10", {
            let mut spec = loaded(None, true, true);
            spec.background = spec.background.map(|b| Background { nice: 10, ..b });
            spec
        });
        push(
            s,
            "frames saturating, QoS, TCP, kernel socket buffers",
            CaseSpec { tcp_buffer: TcpBuffer::Kernel, ..loaded(None, true, false) },
        );
        push(
            s,
            "frames saturating, QoS, TCP, zenoh's runtime",
            CaseSpec { runtime: Some(ZENOH_OWN_RUNTIME.into()), ..loaded(None, true, false) },
        );
    }
    out
}

/// A child process that is killed if still running when dropped.
struct Peer(Child);

impl Drop for Peer {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// The seed design's peer (Python, standard library), shipped inside the binary.
const SEED_PEER: &str = include_str!("seed_udp.py");
/// The Python that runs it.
const PYTHON: &str = "python3";

/// Whether the seed's Python peer can run here.
fn python_available() -> bool {
    Command::new(PYTHON)
        .arg("--version")
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success())
}

/// Where the seed peer's script was written (removed at the end of the run).
static SEED_SCRIPT: std::sync::OnceLock<std::path::PathBuf> = std::sync::OnceLock::new();

/// The seed peer's script, written once per process into the temp directory.
fn seed_peer_script() -> Result<std::path::PathBuf> {
    if let Some(p) = SEED_SCRIPT.get() {
        return Ok(p.clone());
    }
    let path = std::env::temp_dir().join(format!("slipstream-seed-udp-{}.py", std::process::id()));
    std::fs::write(&path, SEED_PEER).with_context(|| format!("write {}", path.display()))?;
    Ok(SEED_SCRIPT.get_or_init(|| path).clone())
}

fn remove_seed_script() {
    if let Some(p) = SEED_SCRIPT.get() {
        let _ = std::fs::remove_file(p);
    }
}

/// The bench's child processes log warnings only (SLIPSTREAM_BENCH_LOG overrides): progress
/// is the parent's job.
fn child_log_filter() -> String {
    std::env::var("SLIPSTREAM_BENCH_LOG").unwrap_or_else(|_| "warn,zenoh=error".into())
}

fn spawn_peer(role: &str, spec: &CaseSpec, endpoints: &[String]) -> Result<Peer> {
    let mut cmd = if spec.transport == Transport::SeedPythonUdp {
        let mut c = Command::new(PYTHON);
        c.arg(seed_peer_script()?);
        c
    } else {
        let exe = match &spec.peer_exe {
            Some(exe) => std::path::PathBuf::from(exe),
            None => std::env::current_exe().context("find the slipstream binary")?,
        };
        let mut c = Command::new(exe);
        c.arg("bench-peer");
        c
    };
    cmd.arg(role).arg("--spec").arg(serde_json::to_string(spec)?);
    for ep in endpoints {
        cmd.arg("--endpoint").arg(ep);
    }
    // None: the peer applies slipstream's default layout itself.
    match &spec.runtime {
        Some(r) => cmd.env("ZENOH_RUNTIME", r),
        None => cmd.env_remove("ZENOH_RUNTIME"),
    };
    cmd.env("RUST_LOG", child_log_filter());
    if let Some(cpu) = spec.pin_cpu {
        use std::os::unix::process::CommandExt;
        // SAFETY: between fork and exec only async-signal-safe calls: sched_setaffinity on
        // the child itself, with a set built on its stack.
        unsafe {
            cmd.pre_exec(move || {
                let mut set: libc::cpu_set_t = std::mem::zeroed();
                libc::CPU_SET(cpu, &mut set);
                match libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &set) {
                    0 => Ok(()),
                    _ => Err(std::io::Error::last_os_error()),
                }
            });
        }
    }
    cmd.stdin(Stdio::piped()).stdout(Stdio::piped()).stderr(Stdio::inherit());
    Ok(Peer(cmd.spawn().context("spawn bench peer")?))
}

/// Reads lines until one starts with `tag`, within `timeout`.
fn read_tagged(out: &mut BufReader<std::process::ChildStdout>, tag: &str, timeout: Duration) -> Result<String> {
    let deadline = Instant::now() + timeout;
    let mut line = String::new();
    loop {
        line.clear();
        if out.read_line(&mut line)? == 0 {
            bail!("peer exited before printing {tag}");
        }
        if let Some(rest) = line.trim_end().strip_prefix(tag) {
            return Ok(rest.trim().to_string());
        }
        if Instant::now() > deadline {
            bail!("no {tag} within {timeout:?}");
        }
    }
}

fn run_case(spec: &CaseSpec) -> Result<(SendReport, RecvReport)> {
    let (sent, mut received) = run_groups(std::slice::from_ref(spec), None)?.pop().context("one group, one result")?;
    Ok((sent, received.pop().context("one receiver")?))
}

/// Runs senders side by side, each with `spec.subscribers` receivers of its own (all ready
/// before any sender starts), directly or through the router at `router`; returns each
/// sender's report with its receivers'.
fn run_groups(specs: &[CaseSpec], router: Option<&str>) -> Result<Vec<(SendReport, Vec<RecvReport>)>> {
    let router: Vec<String> = router.into_iter().map(String::from).collect();
    let mut receivers = Vec::new();
    let mut endpoints = Vec::new();
    for spec in specs {
        let mut group = Vec::new();
        let mut eps = Vec::new();
        for _ in 0..spec.subscribers.max(1) {
            let mut recv = spawn_peer("recv", spec, &router)?;
            let mut out = BufReader::new(recv.0.stdout.take().context("receiver stdout")?);
            let ep = read_tagged(&mut out, "READY", Duration::from_secs(20))?;
            if !eps.contains(&ep) {
                eps.push(ep);
            }
            group.push((recv, out));
        }
        receivers.push(group);
        endpoints.push(eps);
    }
    let mut senders = Vec::new();
    for (spec, eps) in specs.iter().zip(&endpoints) {
        let mut send = spawn_peer("send", spec, eps)?;
        let out = BufReader::new(send.0.stdout.take().context("sender stdout")?);
        senders.push((send, out));
    }
    let mut sent = Vec::new();
    for (spec, (_, out)) in specs.iter().zip(&mut senders) {
        let limit = Duration::from_secs_f64(spec.max_duration_s + 30.0);
        sent.push(serde_json::from_str::<SendReport>(&read_tagged(out, "SENT", limit)?)?);
    }
    std::thread::sleep(Duration::from_millis(300));
    for (recv, _) in receivers.iter_mut().flatten() {
        if let Some(mut stdin) = recv.0.stdin.take() {
            let _ = stdin.write_all(b"stop\n");
        }
    }
    let mut out = Vec::new();
    for (s, group) in sent.into_iter().zip(&mut receivers) {
        let mut reports = Vec::new();
        for (_, stdout) in group.iter_mut() {
            reports.push(serde_json::from_str::<RecvReport>(&read_tagged(stdout, "RESULT", Duration::from_secs(30))?)?);
        }
        out.push((s, reports));
    }
    Ok(out)
}

/// A `slipstream router` on a free loopback port, stopped when dropped; its endpoint.
struct RouterProcess {
    process: Peer,
    endpoint: String,
}

impl RouterProcess {
    fn start() -> Result<RouterProcess> {
        let mut cmd = Command::new(std::env::current_exe().context("find the slipstream binary")?);
        cmd.args(["router", "-l", "tcp/127.0.0.1:0", "--no-multicast-scouting"]);
        // The router's own thread layout (`slipstream router` as users run it).
        cmd.env_remove("ZENOH_RUNTIME");
        cmd.env("RUST_LOG", child_log_filter());
        cmd.stdin(Stdio::null()).stdout(Stdio::piped()).stderr(Stdio::inherit());
        let mut process = Peer(cmd.spawn().context("start slipstream router")?);
        let mut out = BufReader::new(process.0.stdout.take().context("router stdout")?);
        let line = read_tagged(&mut out, "router", Duration::from_secs(20))?;
        let endpoint = line
            .split_once("listening on ")
            .and_then(|(_, eps)| eps.split(", ").find(|e| e.starts_with("tcp/")))
            .with_context(|| format!("the router printed no tcp endpoint: {line}"))?
            .to_string();
        Ok(RouterProcess { process, endpoint })
    }

    /// CPU seconds (user + system) the router has used so far.
    fn cpu_s(&self) -> f64 {
        process_cpu_s(self.process.0.id()).unwrap_or(0.0)
    }

    /// The most memory the router has held so far, MiB.
    fn peak_rss_mib(&self) -> Option<f64> {
        process_peak_rss_mib(self.process.0.id())
    }
}

/// The peak resident memory of a running process (VmHWM in /proc/PID/status), MiB.
fn process_peak_rss_mib(pid: u32) -> Option<f64> {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kib: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib / 1024.0)
}

/// User + system CPU seconds of a running process (/proc/PID/stat), None if unreadable.
pub(super) fn process_cpu_s(pid: u32) -> Option<f64> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    // Fields after the command name (which may hold spaces) in parentheses.
    let rest = &stat[stat.rfind(')')? + 2..];
    let fields: Vec<&str> = rest.split_whitespace().collect();
    let ticks = fields.get(11)?.parse::<f64>().ok()? + fields.get(12)?.parse::<f64>().ok()?;
    // SAFETY: sysconf only reads a configuration value.
    let hz = unsafe { libc::sysconf(libc::_SC_CLK_TCK) } as f64;
    Some(ticks / hz.max(1.0))
}

fn percentile(sorted: &[i64], p: f64) -> Option<f64> {
    if sorted.is_empty() {
        return None;
    }
    let i = ((sorted.len() - 1) as f64 * p).round() as usize;
    Some(sorted[i] as f64 / 1000.0)
}

/// The median of the values present.
pub fn median(values: impl IntoIterator<Item = Option<f64>>) -> Option<f64> {
    let mut v: Vec<f64> = values.into_iter().flatten().filter(|x| x.is_finite()).collect();
    if v.is_empty() {
        return None;
    }
    v.sort_by(|a, b| a.total_cmp(b));
    let n = v.len();
    Some(if n % 2 == 1 { v[n / 2] } else { (v[n / 2 - 1] + v[n / 2]) / 2.0 })
}

struct RunFigures {
    sent: f64,
    received: f64,
    lost: f64,
    p50: Option<f64>,
    p99: Option<f64>,
    max: Option<f64>,
    fps: Option<f64>,
    mbps: Option<f64>,
    shm: f64,
    bg_fps: Option<f64>,
}

fn figures(spec: &CaseSpec, s: &SendReport, r: &RecvReport) -> RunFigures {
    let mut lat = r.latencies_ns.clone();
    lat.sort_unstable();
    let throughput = spec.rate_hz.is_none() && r.received >= 2 && r.span_s > 0.0;
    RunFigures {
        sent: s.sent as f64,
        received: r.received as f64,
        lost: s.sent.saturating_sub(r.received) as f64,
        p50: percentile(&lat, 0.5),
        p99: percentile(&lat, 0.99),
        max: lat.last().map(|x| *x as f64 / 1000.0),
        fps: throughput.then(|| (r.received - 1) as f64 / r.span_s),
        mbps: throughput.then(|| r.bytes as f64 / r.span_s / 1e6),
        shm: r.shared_memory as f64,
        bg_fps: spec.background.map(|_| r.background_received as f64 / s.elapsed_s.max(1e-3)),
    }
}

/// Runs the suites; progress goes to stderr.
pub fn run(args: &BenchArgs) -> Result<BenchReport> {
    if cfg!(debug_assertions) {
        eprintln!("warning: this is a debug build; figures mean little. Use `cargo run --release -- bench`.");
    }
    let suites = if args.suites.is_empty() {
        vec![Suite::Speed, Suite::Frames, Suite::Contention, Suite::Sim, Suite::Fanout, Suite::Router]
    } else {
        args.suites.clone()
    };
    let repeat = if args.quick { 1 } else { args.repeat.max(1) };
    let builds = other_builds(&args.with_build)?;
    let all = cases(&suites, args.quick, &builds);
    let mut rows = Vec::new();
    let total = all.len() * repeat;
    let mut done = 0;
    for case in &all {
        let mut runs = Vec::new();
        for _ in 0..repeat {
            done += 1;
            eprint!("[{done}/{total}] {} / {} ... ", case.suite, case.path);
            let result = run_case(&case.spec).with_context(|| format!("{} / {}", case.suite, case.path));
            if result.is_err() {
                remove_seed_script();
            }
            let (s, r) = result?;
            let f = figures(&case.spec, &s, &r);
            eprintln!(
                "{} sent, {} received{}",
                s.sent,
                r.received,
                f.p50.map(|p| format!(", p50 {p:.0} us")).unwrap_or_default()
            );
            runs.push(f);
        }
        let med = |f: &dyn Fn(&RunFigures) -> Option<f64>| median(runs.iter().map(f));
        rows.push(Row {
            suite: case.suite.clone(),
            path: case.path.clone(),
            runs: runs.len(),
            sent: med(&|r| Some(r.sent)).unwrap_or(0.0),
            received: med(&|r| Some(r.received)).unwrap_or(0.0),
            lost: med(&|r| Some(r.lost)).unwrap_or(0.0),
            p50_us: med(&|r| r.p50),
            p99_us: med(&|r| r.p99),
            max_us: med(&|r| r.max),
            frames_per_s: med(&|r| r.fps),
            mb_per_s: med(&|r| r.mbps),
            shared_memory_frames: med(&|r| Some(r.shm)).unwrap_or(0.0),
            background_frames_per_s: med(&|r| r.bg_fps),
        });
    }
    remove_seed_script();
    let ratios = ratios(&rows, &builds);
    let sim = if suites.contains(&Suite::Sim) { sim::run(args.quick, repeat)? } else { Vec::new() };
    let scale = match suites.contains(&Suite::Scale) {
        true if args.quick => scale::run(&[1, 2], 3.0)?,
        true => {
            anyhow::ensure!(
                !args.loops.is_empty() && args.loops.iter().all(|n| (1..=32).contains(n)),
                "--loops: give 1 to 32 loops per batch, e.g. --loops 1,2,4,8"
            );
            anyhow::ensure!(args.scale_seconds >= 1.0, "--scale-seconds must be at least 1");
            scale::run(&args.loops, args.scale_seconds)?
        }
        false => Vec::new(),
    };
    let counts = |asked: &[usize], what: &str, max: usize| -> Result<Vec<usize>> {
        anyhow::ensure!(
            !asked.is_empty() && asked.iter().all(|n| (1..=max).contains(n)),
            "--{what}: give 1 to {max} per run, e.g. --{what} 1,2,4,8"
        );
        Ok(if args.quick { vec![1, 2] } else { asked.to_vec() })
    };
    let fanout = match suites.contains(&Suite::Fanout) {
        true => growth::fanout(&counts(&args.subscribers, "subscribers", 32)?, args.quick, repeat)?,
        false => Vec::new(),
    };
    let router = match suites.contains(&Suite::Router) {
        true => growth::router(&counts(&args.vehicles, "vehicles", 64)?, args.quick, repeat)?,
        false => Vec::new(),
    };
    let fleet = match suites.contains(&Suite::Fleet) {
        true => {
            anyhow::ensure!(args.fleet_seconds >= 5.0, "--fleet-seconds must be at least 5");
            anyhow::ensure!(
                !args.fleet_vehicles.is_empty() && args.fleet_vehicles.iter().all(|n| (1..=64).contains(n)),
                "--fleet-vehicles: give 1 to 64 per run, e.g. --fleet-vehicles 1,2,4,8"
            );
            let plan = fleet::FleetPlan {
                vehicles: args.fleet_vehicles.clone(),
                caps_mbit_s: args.fleet_caps.clone(),
                seconds: if args.quick { 5.0 } else { args.fleet_seconds },
                frames: args.fleet_frames.clone(),
                cfg: args.fleet_cfg.clone(),
                routers: args.fleet_routers,
            };
            anyhow::ensure!(
                plan.caps_mbit_s.iter().all(|c| (1..=100_000).contains(c)),
                "--fleet-caps: give link speeds in Mbit/s, e.g. --fleet-caps 1000,100"
            );
            fleet::run(&plan)?
        }
        false => Vec::new(),
    };
    let command = std::env::args().collect::<Vec<_>>().join(" ");
    let report = BenchReport { command, rows, ratios, sim, scale, fanout, router, fleet };
    if let Some(path) = &args.plot {
        plot::growth(&report, path)?;
        eprintln!("plot: {}", path.display());
    }
    Ok(report)
}

fn find<'a>(rows: &'a [Row], suite_prefix: &str, path: &str) -> Option<&'a Row> {
    rows.iter().find(|r| r.suite.starts_with(suite_prefix) && r.path == path)
}

fn ratios(rows: &[Row], builds: &[OtherBuild]) -> Vec<Ratio> {
    let mut out = Vec::new();
    let mut ratio = |what: String, a: Option<f64>, b: Option<f64>, aim: &str| {
        if let (Some(a), Some(b)) = (a, b) {
            if b > 0.0 {
                out.push(Ratio { what, value: a / b, aim: aim.into() });
            }
        }
    };
    let p50 = |s: &str, p: &str| find(rows, s, p).and_then(|r| r.p50_us);
    let p99 = |s: &str, p: &str| find(rows, s, p).and_then(|r| r.p99_us);
    ratio("speed p50: bus / seed Python UDP".into(), p50("a.", "bus"), p50("a.", "seed: Python UDP"), "< 1");
    ratio("speed p50: bus / raw UDP".into(), p50("a.", "bus"), p50("a.", "raw UDP"), "<= 2 (moonshot 1.5)");
    ratio("speed p50: bus, unix socket / bus".into(), p50("a.", "bus, unix socket"), p50("a.", "bus"), "-");
    ratio(
        "speed p50: bus, unix socket / seed Python UDP".into(),
        p50("a.", "bus, unix socket"),
        p50("a.", "seed: Python UDP"),
        "< 1",
    );
    ratio(
        "speed p50: bus, lowlatency transport, unix socket / seed Python UDP".into(),
        p50("a.", "bus, lowlatency transport, unix socket"),
        p50("a.", "seed: Python UDP"),
        "< 1",
    );
    ratio("speed p50: bus, unix socket / raw UDP".into(), p50("a.", "bus, unix socket"), p50("a.", "raw UDP"), "<= 2");
    ratio("speed p50: bus / raw zenoh".into(), p50("a.", "bus"), p50("a.", "raw zenoh"), "<= 1.1");
    for b in builds {
        let l = &b.label;
        ratio(format!("speed p50: bus, {l} / bus"), p50("a.", &format!("bus, {l}")), p50("a.", "bus"), "-");
        ratio(
            format!("speed p50: bus, unix socket, {l} / bus, unix socket"),
            p50("a.", &format!("bus, unix socket, {l}")),
            p50("a.", "bus, unix socket"),
            "-",
        );
        ratio(
            format!("speed p50: bus, unix socket, {l} / seed Python UDP"),
            p50("a.", &format!("bus, unix socket, {l}")),
            p50("a.", "seed: Python UDP"),
            "< 1",
        );
    }
    ratio("speed p50: bus / raw TCP".into(), p50("a.", "bus"), p50("a.", "raw TCP"), "-");
    for lead in ["bus, kernel socket buffers", "bus, both peers on one core"] {
        ratio(format!("speed p50: {lead} / bus"), p50("a.", lead), p50("a.", "bus"), "-");
    }
    ratio("speed p99: bus / raw UDP".into(), p99("a.", "bus"), p99("a.", "raw UDP"), "-");
    ratio(
        "speed p50: bus, zenoh's runtime / raw zenoh, zenoh's runtime".into(),
        p50("a.", "bus, zenoh's runtime"),
        p50("a.", "raw zenoh, zenoh's runtime"),
        "<= 1.1",
    );
    ratio("speed p50: bus, zenoh's runtime / bus".into(), p50("a.", "bus, zenoh's runtime"), p50("a.", "bus"), "-");
    ratio(
        "speed p50: bus, lowlatency transport / raw UDP".into(),
        p50("a.", "bus, lowlatency transport"),
        p50("a.", "raw UDP"),
        "<= 1.5",
    );
    for size in ["640x480", "1280x720"] {
        let fps = |p: &str| {
            rows.iter()
                .find(|r| r.suite.contains(size) && r.suite.contains("throughput") && r.path == p)
                .and_then(|r| r.frames_per_s)
        };
        ratio(format!("{size} frames/s: bus shm / raw TCP"), fps("bus, shared memory"), fps("raw TCP"), ">= 3");
        ratio(
            format!("{size} frames/s: bus TCP / raw zenoh TCP"),
            fps("bus, TCP (shm off)"),
            fps("raw zenoh, TCP (shm off)"),
            ">= 0.9",
        );
        let lat = |p: &str| {
            rows.iter()
                .find(|r| r.suite.contains(size) && r.suite.contains("latency") && r.path == p)
                .and_then(|r| r.p50_us)
        };
        ratio(
            format!("{size} @20 Hz p50: shm, unix socket: callback reader / latest-only reader"),
            lat("bus, shared memory, unix socket, callback reader"),
            lat("bus, shared memory, unix socket"),
            "-",
        );
        ratio(
            format!("{size} frames/s: bus shm / raw zenoh implicit shm"),
            fps("bus, shared memory"),
            fps("raw zenoh, implicit shm"),
            "-",
        );
    }
    let c = "c.";
    for p in [
        "frames 30 Hz, QoS, TCP",
        "frames saturating, QoS, TCP",
        "frames saturating, QoS off, TCP",
        "frames saturating, QoS, TCP, kernel socket buffers",
        "frames saturating, QoS, shm",
        "frames saturating, QoS, shm, frame thread at nice 10",
    ] {
        ratio(format!("speed p99 {p} / unloaded"), p99(c, p), p99(c, "unloaded"), "<= 3 (with QoS)");
    }
    out
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
    if !report.ratios.is_empty() {
        s.push_str("\n### Ratios (same run)\n\n| ratio | value | aim |\n|---|---|---|\n");
        for r in &report.ratios {
            s.push_str(&format!("| {} | {:.2} | {} |\n", r.what, r.value, r.aim));
        }
    }
    s
}
