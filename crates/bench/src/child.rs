//! The bench's child processes: the two peers of a case (`slipstream bench-peer`, or the
//! seed's Python script), directly or through a router (`launch::LocalRouter`, which growth.rs
//! starts), and what /proc says of them.

use std::io::{BufRead, BufReader, Write};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};

use super::spec::{CaseSpec, RecvReport, SendReport};

/// A child process that is killed if still running when dropped.
pub(super) struct Peer(pub(super) Child);

impl Drop for Peer {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// The seed design's peers (Python, standard library), shipped inside the binary.
const SEED_PEER: &str = include_str!("seed.py");
/// The Python that runs it.
pub(super) const PYTHON: &str = "python3";

/// Whether the seed's Python peer can run here.
pub(super) fn python_available() -> bool {
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

pub(super) fn remove_seed_script() {
    if let Some(p) = SEED_SCRIPT.get() {
        let _ = std::fs::remove_file(p);
    }
}

/// The bench's child processes log warnings only (SLIPSTREAM_BENCH_LOG overrides): progress
/// is the parent's job. Not the frame publisher's "shared-memory pool full": the throughput
/// cases saturate the pool on purpose, and the `shm frames` column counts what went from the
/// heap instead.
pub(super) fn child_log_filter() -> String {
    std::env::var("SLIPSTREAM_BENCH_LOG")
        .unwrap_or_else(|_| "warn,zenoh=error,slipstream::bus::frame_publisher=error".into())
}

pub(super) fn spawn_peer(role: &str, spec: &CaseSpec, endpoints: &[String]) -> Result<Peer> {
    let mut cmd = if spec.transport.is_seed() {
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
pub(super) fn read_tagged(
    out: &mut BufReader<std::process::ChildStdout>,
    tag: &str,
    timeout: Duration,
) -> Result<String> {
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

pub(super) fn run_case(spec: &CaseSpec) -> Result<(SendReport, RecvReport)> {
    let (sent, mut received) = run_groups(std::slice::from_ref(spec), None)?.pop().context("one group, one result")?;
    Ok((sent, received.pop().context("one receiver")?))
}

/// Runs senders side by side, each with `spec.subscribers` receivers of its own (all ready
/// before any sender starts), directly or through the router at `router`; returns each
/// sender's report with its receivers'.
pub(super) fn run_groups(specs: &[CaseSpec], router: Option<&str>) -> Result<Vec<(SendReport, Vec<RecvReport>)>> {
    let router: Vec<String> = router.into_iter().map(String::from).collect();
    let mut receivers = Vec::new();
    let mut endpoints = Vec::new();
    for spec in specs {
        let mut group = Vec::new();
        let mut eps = Vec::new();
        for _ in 0..spec.subscribers.max(1) {
            let mut recv = spawn_peer("recv", spec, &router)?;
            let mut out = BufReader::new(recv.0.stdout.take().context("receiver stdout")?);
            // The receiver's endpoints: its main session's, then its low-latency session's.
            for ep in read_tagged(&mut out, "READY", Duration::from_secs(20))?.split_whitespace() {
                if !eps.iter().any(|e| e == ep) {
                    eps.push(ep.to_string());
                }
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

/// The peak resident memory of a running process (VmHWM in /proc/PID/status), MiB.
pub(crate) fn process_peak_rss_mib(pid: u32) -> Option<f64> {
    let status = procfs::process::Process::new(i32::try_from(pid).ok()?).ok()?.status().ok()?;
    Some(status.vmhwm? as f64 / 1024.0)
}

/// User + system CPU seconds of a running process (/proc/PID/stat), None if unreadable.
pub(crate) fn process_cpu_s(pid: u32) -> Option<f64> {
    let stat = procfs::process::Process::new(i32::try_from(pid).ok()?).ok()?.stat().ok()?;
    Some((stat.utime + stat.stime) as f64 / procfs::ticks_per_second().max(1) as f64)
}
