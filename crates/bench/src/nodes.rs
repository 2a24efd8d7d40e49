//! `slipstream bench nodes`: what a controller of the user's own costs the loop, against
//! slipstream-acc in the same run. The same generated sweep (`eval sweep`, ground truth, one
//! run at a time, one seed) runs with slipstream-acc, with the Python SDK's example controller
//! (clients/python/examples/own_acc.py) and with the Rust SDK's (own-controller beside this
//! binary), interleaved repeat by repeat so that a drift of the machine touches each alike.
//!
//! Per controller: the sweep's wall time, and the simulator's lockstep wait per answered step
//! (its `awaiting` time over the steps the observer saw: the round trip to the controller,
//! transport and the controller's computing), with the difference to slipstream-acc's: the
//! per-step cost a controller adds.

use std::path::{Path, PathBuf};
use std::process::Command;

use anyhow::{Context, Result};
use serde::Serialize;

use super::child::PYTHON;
use super::median;

/// The Python SDK's example controller, from the checkout's root.
const PYTHON_EXAMPLE: &str = "clients/python/examples/own_acc.py";
/// The sweep's seed: every controller drives the same scenarios.
const SEED: u64 = 1;

/// One controller's figures, medians over the repeats.
#[derive(Debug, Clone, Serialize)]
pub struct NodesRow {
    pub controller: String,
    /// `--controller`'s command; None for slipstream-acc.
    pub command: Option<String>,
    pub runs: usize,
    /// Lockstep steps answered per sweep (the observer's vehicle/state count).
    pub steps: u64,
    pub sweep_wall_s: f64,
    pub awaited_per_step_us: f64,
    /// Against slipstream-acc's in the same run.
    pub wall_vs_ours: f64,
    pub added_per_step_us: f64,
}

/// One sweep's figures.
struct Sweep {
    wall_s: f64,
    steps: u64,
    awaiting_s: f64,
}

/// The controllers this checkout can run: slipstream-acc always; the Python example when
/// its file is here and python3 imports zenoh; the Rust example when it is built beside us.
fn controllers(exe: &Path) -> Vec<(String, Option<String>)> {
    let mut out = vec![("slipstream-acc".to_string(), None)];
    let zenoh = Command::new(PYTHON).args(["-c", "import zenoh"]).output().is_ok_and(|o| o.status.success());
    match (Path::new(PYTHON_EXAMPLE).is_file(), zenoh) {
        (true, true) => out.push(("Python SDK (own_acc.py)".into(), Some(format!("{PYTHON} {PYTHON_EXAMPLE}")))),
        (false, _) => eprintln!("note: no {PYTHON_EXAMPLE} here (run from a checkout): its row is left out"),
        (true, false) => eprintln!(
            "note: {PYTHON} cannot import zenoh (pip install eclipse-zenoh==1.10.*): the Python row is left out"
        ),
    }
    let rust = exe.with_file_name("own-controller");
    match rust.is_file() {
        true => out.push(("Rust SDK (own-controller)".into(), Some(rust.display().to_string()))),
        false => {
            eprintln!("note: {} is not built (cargo build --release --workspace): its row is left out", rust.display())
        }
    }
    out
}

/// Runs the sweep once with `command` as the controller (None: slipstream-acc).
fn sweep(exe: &Path, command: Option<&str>, count: usize, dir: &Path) -> Result<Sweep> {
    let mut cmd = Command::new(exe);
    cmd.args(["eval", "sweep", "--perception", "ground-truth", "-j", "1"]);
    cmd.args(["--count", &count.to_string(), "--seed", &SEED.to_string()]).arg("--report").arg(dir);
    if let Some(c) = command {
        cmd.args(["--controller", c]);
    }
    let done = cmd.output().context("start eval sweep")?;
    // 1: a run missed an aim (a teaching controller does); the figures are still the sweep's.
    anyhow::ensure!(
        matches!(done.status.code(), Some(0 | 1)),
        "eval sweep exited {}: {}",
        done.status,
        String::from_utf8_lossy(&done.stderr).lines().last().unwrap_or("")
    );
    let path = dir.join("sweep.json");
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&path).with_context(|| format!("read {}", path.display()))?)?;
    let results: Vec<&serde_json::Value> =
        report["runs"].as_array().into_iter().flatten().filter_map(|r| r.get("result")).collect();
    let steps = results
        .iter()
        .flat_map(|r| r["inputs"].as_array().into_iter().flatten())
        .filter(|i| i["node"] == "observer" && i["topic"] == "vehicle/state");
    Ok(Sweep {
        wall_s: report["wall_s"].as_f64().context("sweep.json has no wall_s")?,
        steps: steps.filter_map(|i| i["received"].as_u64()).sum(),
        awaiting_s: results.iter().filter_map(|r| r["time"]["sim"]["awaiting_s"].as_f64()).sum(),
    })
}

/// Runs the suite; progress on stderr.
pub(crate) fn run(quick: bool, repeat: usize) -> Result<Vec<NodesRow>> {
    let exe = std::env::current_exe().context("this binary's path")?;
    let count = if quick { 2 } else { 10 };
    let repeat = if quick { 1 } else { repeat.max(1) };
    let who = controllers(&exe);
    let scratch = std::env::temp_dir().join(format!("slipstream-bench-nodes-{}", std::process::id()));
    let mut sweeps: Vec<Vec<Sweep>> = who.iter().map(|_| Vec::new()).collect();
    for i in 0..repeat {
        for (k, (name, command)) in who.iter().enumerate() {
            eprint!("[nodes {}/{repeat}] eval sweep --count {count}, {name} ... ", i + 1);
            let dir: PathBuf = scratch.join(format!("{k}-{i}"));
            let s = sweep(&exe, command.as_deref(), count, &dir).with_context(|| format!("bench nodes: {name}"))?;
            eprintln!("{:.1} s, {:.0} us awaited per step", s.wall_s, s.awaiting_s / s.steps.max(1) as f64 * 1e6);
            sweeps[k].push(s);
        }
    }
    let _ = std::fs::remove_dir_all(&scratch);
    let per = |s: &[Sweep]| {
        let wall = median(s.iter().map(|x| Some(x.wall_s))).unwrap_or(f64::NAN);
        let step_us = median(s.iter().map(|x| Some(x.awaiting_s / x.steps.max(1) as f64 * 1e6))).unwrap_or(f64::NAN);
        (wall, step_us, s.first().map_or(0, |x| x.steps))
    };
    let (ours_wall, ours_step, _) = per(&sweeps[0]);
    Ok(who
        .into_iter()
        .zip(&sweeps)
        .map(|((controller, command), s)| {
            let (wall, step_us, steps) = per(s);
            NodesRow {
                controller,
                command,
                runs: s.len(),
                steps,
                sweep_wall_s: wall,
                awaited_per_step_us: step_us,
                wall_vs_ours: wall / ours_wall,
                added_per_step_us: step_us - ours_step,
            }
        })
        .collect())
}

/// The suite's table.
pub(crate) fn markdown(rows: &[NodesRow]) -> String {
    let mut s = String::from(
        "\n### i. your own controller against slipstream-acc (eval sweep, ground truth, -j 1, same run)\n\n| controller | steps | sweep wall s | x slipstream-acc | awaited per step us | added per step us |\n|---|---|---|---|---|---|\n",
    );
    for r in rows {
        s.push_str(&format!(
            "| {} | {} | {:.1} | {:.2} | {:.0} | {:+.0} |\n",
            r.controller, r.steps, r.sweep_wall_s, r.wall_vs_ours, r.awaited_per_step_us, r.added_per_step_us
        ));
    }
    s
}
