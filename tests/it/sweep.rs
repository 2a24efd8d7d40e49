//! `slipstream eval sweep` end to end: generated scenarios from every family run through the
//! loop's processes, summed into rates, the worst kept as files that replay with `eval acc`;
//! and a seeded sample of tests/scenarios with both perceptions (the wider net, in CI).

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::Duration;

use serde_json::Value;

use crate::common;

fn slipstream() -> Command {
    common::bin("slipstream")
}

fn run(cmd: Command, limit: Duration) -> Output {
    common::run_with_limit(cmd, limit)
}

/// Writes `text` to target/test-reports/`name` (scripts/test.sh prints it): what a run of the
/// suite measured, for the reader of its log.
fn write_report(name: &str, text: &str) {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("target/test-reports");
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join(name), text).unwrap();
}

fn f(v: &Value) -> f64 {
    v.as_f64().unwrap_or_else(|| panic!("not a number: {v}"))
}

/// `eval sweep` into `out`; its report.
fn sweep(out: &Path, args: &[&str]) -> (Value, Output) {
    let mut c = slipstream();
    c.args(["eval", "sweep", "--json", "--report"]).arg(out).args(args);
    let done = run(c, Duration::from_secs(900));
    let report: Value = serde_json::from_slice(&done.stdout)
        .unwrap_or_else(|e| panic!("{e}: {}", String::from_utf8_lossy(&done.stderr)));
    (report, done)
}

#[test]
fn a_sweep_of_forty_covers_every_family_sums_rates_and_keeps_replayable_files() {
    let _serial = common::serial();
    let out = std::env::temp_dir().join(format!("slipstream-sweep-{}", std::process::id()));
    let (report, done) = sweep(&out, &["--count", "40", "--seed", "3"]);

    let all = &report["all"];
    assert_eq!((all["runs"].as_u64(), all["errors"].as_u64()), (Some(40), Some(0)), "{all}");
    let families = report["families"].as_array().unwrap();
    assert_eq!(families.len(), 10, "every family has its share of 40");
    let mut km = 0.0;
    for fam in families {
        assert_eq!(fam["runs"], 4, "{fam}");
        let per = |k: &str| f(&fam["per_1000_km"][k]);
        let rate = |k: &str| f(&fam[k]) * 1000.0 / f(&fam["km"]);
        assert!(f(&fam["km"]) > 0.0, "{fam}");
        for k in ["collisions", "unwarranted_emergencies", "phantom_braking_events"] {
            assert!((per(k) - rate(k)).abs() < 1e-6, "{k}: {fam}");
        }
        km += f(&fam["km"]);
    }
    assert!((km - f(&all["km"])).abs() < 1e-6);
    let rows: Vec<String> = families
        .iter()
        .chain(std::iter::once(all))
        .map(|r| {
            let p = &r["per_1000_km"];
            format!(
                "{:16} runs {:>2} passed {:>2} km {:>5.1} collisions {} unwarranted emergencies {} ({:.0}/1000 km) phantom events {} ({:.0}/1000 km)",
                r["family"].as_str().unwrap(), r["runs"], r["passed"], f(&r["km"]), r["collisions"],
                r["unwarranted_emergencies"], f(&p["unwarranted_emergencies"]), r["phantom_braking_events"], f(&p["phantom_braking_events"])
            )
        })
        .collect();
    write_report("sweep-40.txt", &format!("eval sweep --count 40 --seed 3 (camera):\n{}\n", rows.join("\n")));
    // The exit status says what the report says.
    assert_eq!(done.status.success(), report["pass"].as_bool().unwrap(), "{}", report["pass"]);
    assert!(out.join("sweep.json").is_file() && out.join("rates.png").is_file());
    // Every run's file is there and is a scenario, declaring what it warrants.
    let runs = report["runs"].as_array().unwrap();
    for r in runs {
        let file = PathBuf::from(r["file"].as_str().unwrap());
        let s = slipstream::sim::Scenario::load(&file).unwrap_or_else(|e| panic!("{}: {e}", file.display()));
        assert!(s.expect.braking.is_some(), "{}", file.display());
    }
    // A run replays with `eval acc --scenario FILE` (lockstep: the same run). The worst if
    // any, else the first.
    let name = report["worst"].as_array().unwrap().first().and_then(Value::as_str).unwrap_or("ncap-stationary-0000");
    let swept = runs.iter().find(|r| r["name"] == name).unwrap();
    let mut c = slipstream();
    c.args(["eval", "acc", "--json", "--scenario", swept["file"].as_str().unwrap()]);
    let replay: Value = serde_json::from_slice(&run(c, Duration::from_secs(300)).stdout).unwrap();
    let (a, b) = (&swept["result"]["metrics"], &replay["results"][0]["metrics"]);
    assert!((f(&a["distance_m"]) - f(&b["distance_m"])).abs() < 0.01 * f(&a["distance_m"]) + 1.0, "{a}\n{b}");
    assert_eq!(a["collisions"], b["collisions"], "{name}");
    std::fs::remove_dir_all(&out).ok();
}

#[test]
fn bad_sweep_arguments_are_refused_before_anything_runs() {
    let out = std::env::temp_dir().join(format!("slipstream-sweep-bad-{}", std::process::id()));
    for (args, says) in
        [(vec!["--count", "0"], "--count"), (vec!["--families", "no-such"], "no-such"), (vec!["--jobs", "0"], "--jobs")]
    {
        let mut c = slipstream();
        c.args(["eval", "sweep", "--report"]).arg(&out).args(&args);
        let done = run(c, Duration::from_secs(60));
        let err = String::from_utf8_lossy(&done.stderr);
        assert!(!done.status.success() && err.contains(says), "{args:?}: {err}");
    }
    assert!(!out.join("logs").exists(), "nothing ran");
    std::fs::remove_dir_all(&out).ok();
}

/// A sample of tests/scenarios, drawn from `SLIPSTREAM_SAMPLE_SEED` or the clock (printed, so
/// a failure can be drawn again), run with both perceptions: every run passes.
#[test]
fn a_seeded_sample_of_the_wider_net_passes_with_both_perceptions() {
    const SAMPLE: usize = 8;
    let _serial = common::serial();
    let seed: u64 = std::env::var("SLIPSTREAM_SAMPLE_SEED").ok().and_then(|s| s.parse().ok()).unwrap_or_else(|| {
        std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_secs())
    });
    let mut files: Vec<PathBuf> = std::fs::read_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/tests/scenarios"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "json5"))
        .collect();
    files.sort();
    assert!(files.len() >= SAMPLE, "{} scenarios", files.len());
    let mut rng = slipstream::sim::SimRng::new(seed);
    let mut sample = Vec::new();
    while sample.len() < SAMPLE {
        let pick = files.remove(rng.below(files.len() as u64) as usize);
        sample.push(pick);
    }
    let names: Vec<String> = sample.iter().map(|p| p.file_stem().unwrap().to_string_lossy().into_owned()).collect();
    let drawn = format!("tests/scenarios sample (SLIPSTREAM_SAMPLE_SEED={seed}): {}", names.join(", "));
    eprintln!("{drawn}");
    write_report("scenario-sample.txt", &format!("{drawn}\n"));
    for perception in ["camera", "ground-truth"] {
        let mut c = slipstream();
        c.args(["eval", "acc", "--json", "--perception", perception]);
        for p in &sample {
            c.arg("--scenario").arg(p);
        }
        let done = run(c, Duration::from_secs(900));
        let report: Value = serde_json::from_slice(&done.stdout)
            .unwrap_or_else(|e| panic!("{perception}: {e}: {}", String::from_utf8_lossy(&done.stderr)));
        for r in report["results"].as_array().unwrap() {
            let m = &r["metrics"];
            assert!(
                m["pass"].as_bool().unwrap(),
                "{perception} {} (SLIPSTREAM_SAMPLE_SEED={seed}): {}",
                r["scenario"],
                m["checks"]
            );
        }
    }
}
