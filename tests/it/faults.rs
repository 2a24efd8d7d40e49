//! Injected faults (`--faults`): repeatable in lockstep, counted apart from real losses, stale
//! inputs seen by the ACC during an outage, refused where lockstep cannot take them; the
//! envelope sweep of `slipstream eval faults`.

use std::path::Path;
use std::process::Command;
use std::time::Duration;

use crate::common;
use crate::common::{free_port, temp_dir};

fn slipstream() -> Command {
    common::bin("slipstream")
}

/// `up` in lockstep with ground truth and `profile`; its report.json.
fn up_with(profile: &Path, dir: &Path, seconds: &str) -> (std::process::Output, Option<serde_json::Value>) {
    let mut cmd = slipstream();
    cmd.args(["-l", &format!("tcp/127.0.0.1:{}", free_port()), "up", "--mode", "lockstep"]);
    cmd.args(["--perception", "ground-truth", "--scenario", "cut-in", "--duration", seconds, "--plain"]);
    cmd.arg("--faults").arg(profile).arg("--report").arg(dir);
    let out = common::run_with_limit(cmd, Duration::from_secs(180));
    let report = std::fs::read_to_string(dir.join("report.json")).ok().map(|t| serde_json::from_str(&t).unwrap());
    (out, report)
}

/// (node, topic) -> (received, lost, injected dropped, delayed, duplicated)
fn inputs(r: &serde_json::Value) -> Vec<(String, String, [u64; 5])> {
    r["inputs"]
        .as_array()
        .expect("inputs in the report")
        .iter()
        .map(|i| {
            let n = |k: &str| i[k].as_u64().unwrap();
            (
                i["node"].as_str().unwrap().to_string(),
                i["topic"].as_str().unwrap().to_string(),
                [n("received"), n("lost"), n("injected_dropped"), n("injected_delayed"), n("injected_duplicated")],
            )
        })
        .collect()
}

fn of<'a>(v: &'a [(String, String, [u64; 5])], node: &str, topic: &str) -> &'a [u64; 5] {
    &v.iter().find(|(n, t, _)| n == node && t == topic).unwrap_or_else(|| panic!("{node} {topic}: {v:?}")).2
}

fn acc_stats(dir: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(dir.join("logs/slipstream-acc.json")).unwrap()).unwrap()
}

#[test]
fn a_lockstep_run_with_faults_repeats_with_its_seed_and_counts_them_apart_from_real_losses() {
    let _serial = common::serial();
    let dir = temp_dir("repeat");
    let profile = |seed: u64| {
        let path = dir.join(format!("seed{seed}.json5"));
        std::fs::write(
            &path,
            format!(
                r#"{{ seed: {seed}, topics: {{
                    "objects": {{ delay_ms: 30, jitter: {{ dist: "exponential", ms: 20 }}, loss: 0.3, burst_len: 3, duplicate: 0.05 }},
                    "vehicle/state": {{ loss: 0.1 }},
                    "vehicle/control": {{ delay_ms: 20, loss: 0.2, at: ["sim"] }} }} }}"#
            ),
        )
        .unwrap();
        path
    };
    let mut runs = Vec::new();
    for (i, seed) in [7u64, 7, 8].into_iter().enumerate() {
        let run_dir = dir.join(format!("run{i}"));
        let (out, report) = up_with(&profile(seed), &run_dir, "6");
        assert!(out.status.success(), "exit {:?}: {}", out.status, String::from_utf8_lossy(&out.stderr));
        let r = report.expect("report.json");
        assert!(r["faults"].as_str().unwrap().contains("seed"), "{}", r["faults"]);
        runs.push((inputs(&r), acc_stats(&run_dir)));
    }
    let (first, acc) = &runs[0];
    // Every speed, state and truth message of the 6 s arrived; none lost on loopback.
    let objects = of(first, "acc", "objects");
    let control = of(first, "sim", "vehicle/control");
    let steps = of(first, "acc", "vehicle/speed")[0];
    assert!((600..=601).contains(&steps), "{steps}");
    assert_eq!(control[0], steps, "every step answered");
    for (what, c) in [("objects", objects), ("control", control)] {
        assert_eq!(c[1], 0, "{what}: nothing lost on the way: {c:?}");
    }
    // Injected: about the shares asked for (30 % bursty of 120 truth messages, 20 % of 600
    // commands), every surviving truth message and command delayed, a few duplicated.
    assert_eq!(objects[0], steps.div_ceil(5), "one truth message per 20 Hz frame");
    assert!((15..=60).contains(&objects[2]), "objects dropped: {objects:?}");
    assert_eq!(objects[3], objects[0] - objects[2], "every delivered one delayed: {objects:?}");
    assert!((70..=170).contains(&control[2]), "control dropped: {control:?}");
    assert_eq!(control[3], control[0] - control[2]);
    assert!(of(first, "acc", "vehicle/state")[2] > 0);
    assert_eq!(of(first, "acc", "vehicle/speed")[2..], [0, 0, 0], "no faults on speed");
    // The lockstep never waited out a step for a dropped input.
    assert_eq!(acc["lockstep_waits_timed_out"], 0);
    assert_eq!(acc["state_waits_timed_out"], 0);
    // The same seed: the same fates and the same controller history; another seed: others.
    assert_eq!(runs[1].0, runs[0].0, "same seed, same injected faults");
    for k in ["commands", "perception_frames", "stale_episodes", "emergencies"] {
        assert_eq!(runs[1].1[k], runs[0].1[k], "{k}");
    }
    assert_ne!(runs[2].0, runs[0].0, "another seed drops other messages");
}

#[test]
fn an_outage_of_perception_makes_the_acc_brake_as_stale_and_resume() {
    let _serial = common::serial();
    let dir = temp_dir("outage");
    let profile = dir.join("outage.json5");
    std::fs::write(&profile, r#"{ topics: { "objects": { outages: [{ from_s: 3, to_s: 5 }] } } }"#).unwrap();
    let (out, report) = up_with(&profile, &dir.join("run"), "8");
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let r = report.unwrap();
    let all = inputs(&r);
    let objects = of(&all, "acc", "objects");
    assert_eq!(objects[2], 40, "2 s of 20 Hz truth dropped: {objects:?}");
    let csv = std::fs::read_to_string(dir.join("run/trace.csv")).unwrap();
    let stale: Vec<f64> = csv
        .lines()
        .skip(1)
        .filter(|l| l.split(',').nth(3) == Some("Stale"))
        .map(|l| l.split(',').next().unwrap().parse().unwrap())
        .collect();
    assert!(!stale.is_empty(), "the ACC saw its perception go stale");
    // Stale from the perception age limit (400 ms) after the outage began, until shortly
    // after it ended (the observer may miss some states: judged from those it has).
    assert!(stale.iter().all(|t| (3.3..5.2).contains(t)), "stale only around the outage: {stale:?}");
    assert!(acc_stats(&dir.join("run"))["stale_episodes"].as_u64().unwrap() >= 1);
}

#[test]
fn faults_a_lockstep_loop_cannot_take_are_refused_with_the_key_and_the_fix() {
    let dir = temp_dir("refused");
    let profile = dir.join("camera.json5");
    std::fs::write(&profile, r#"{ topics: { "camera/front": { loss: 0.1 } } }"#).unwrap();
    let (out, _) = up_with(&profile, &dir.join("run"), "2");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("topics.camera/front") && stderr.contains("fix:"), "{stderr}");
    let bad = dir.join("bad.json5");
    std::fs::write(&bad, r#"{ topics: { "objects": { loss: 2 } } }"#).unwrap();
    let (out, _) = up_with(&bad, &dir.join("run2"), "2");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && stderr.contains("topics.objects.loss"), "{stderr}");
}

#[test]
fn eval_faults_tries_each_axis_in_rising_steps_and_reports_the_envelope() {
    let _serial = common::serial();
    let dir = temp_dir("eval");
    let mut cmd = slipstream();
    cmd.args(["eval", "faults", "--scenario", "steady-follow", "--perception", "ground-truth", "--duration", "4"]);
    cmd.args(["--delays-ms", "50,100", "--losses", "0.3", "--control-losses", "0.1", "--json", "--plot"]);
    cmd.arg(dir.join("envelope.png"));
    let out = common::run_with_limit(cmd, Duration::from_secs(300));
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let r: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let s = &r["scenarios"][0];
    assert_eq!(s["scenario"], "steady-follow");
    let axes = s["axes"].as_array().unwrap();
    let names: Vec<&str> = axes.iter().map(|a| a["axis"].as_str().unwrap()).collect();
    assert_eq!(names, ["perception-delay", "perception-loss", "perception-bursty-loss", "control-loss"]);
    for a in axes {
        let trials = a["trials"].as_array().unwrap();
        assert!(!trials.is_empty());
        // Tried in rising order, stopped at the first failure, the envelope the last that held.
        let failed = trials.iter().position(|t| !t["failure"].is_null());
        if let Some(i) = failed {
            assert_eq!(i, trials.len() - 1, "stops at the first failure: {a}");
        }
        let held: Vec<f64> =
            trials.iter().filter(|t| t["failure"].is_null()).map(|t| t["value"].as_f64().unwrap()).collect();
        assert_eq!(a["envelope"].as_f64().unwrap(), held.last().copied().unwrap_or(0.0), "{a}");
        assert_eq!(a["held_throughout"], failed.is_none());
    }
    let delays: Vec<f64> = axes[0]["trials"].as_array().unwrap().iter().map(|t| t["value"].as_f64().unwrap()).collect();
    assert!(delays == [50.0, 100.0] || delays == [50.0], "{delays:?}");
    let png = std::fs::read(dir.join("envelope.png")).unwrap();
    assert!(png.starts_with(b"\x89PNG"));
}

/// A node with faults reports its inputs once a second on `nodes/<name>/inputs` (what `top`
/// shows); a node without faults publishes nothing there.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_node_with_faults_reports_its_inputs_for_top() {
    let map = slipstream::TopicMap::default();
    let (tool, mut node) = common::bus_pair(map.clone(), map.clone()).await;
    let profile =
        slipstream::config::FaultProfile::parse(r#"{ topics: { "objects": { loss: 1.0 } } }"#, "test", "all-lost")
            .unwrap();
    node.inject_faults(profile);
    let objects = node.subscriber(slipstream::topics::OBJECTS).await.unwrap();
    let key = map.node_inputs_key(node.node()).unwrap();
    assert_eq!(map.node_of_inputs_key(key.as_str()).as_deref(), Some(node.node()));
    let reports = std::sync::Arc::new(std::sync::Mutex::new(Vec::new()));
    let into = reports.clone();
    let _sub = tool
        .subscribe_samples(key.clone(), false, move |s| into.lock().unwrap().push(s.payload().to_bytes().into_owned()))
        .await
        .unwrap();
    let publisher = tool.publisher(slipstream::topics::OBJECTS).await.unwrap();
    assert!(publisher.wait_for_subscriber(Duration::from_secs(10)).await);
    // Messages go out at a pace until five have arrived: a loaded machine may drop some on
    // the way (realtime QoS), and what is asserted is the split between real and injected
    // losses, not that the network lost nothing.
    let truth = slipstream::msg::GroundTruthObjects { step: 1, objects: Vec::new() };
    let deadline = std::time::Instant::now() + Duration::from_secs(30);
    let mut sent = 0u64;
    let report = loop {
        let last = reports.lock().unwrap().last().cloned();
        let row = last.and_then(|r| {
            let v: serde_json::Value = serde_json::from_slice(&r).unwrap();
            v["inputs"].as_array().unwrap().iter().find(|i| i["topic"] == "objects").cloned()
        });
        if let Some(row) = row.filter(|o| o["received"].as_u64().unwrap_or(0) >= 5) {
            break row;
        }
        assert!(
            std::time::Instant::now() < deadline && sent < 300,
            "no inputs report with 5 messages after {sent} sent"
        );
        publisher.put(sent * 50_000_000, &truth).unwrap();
        sent += 1;
        tokio::time::sleep(Duration::from_millis(100)).await;
    };
    let received = report["received"].as_u64().unwrap();
    assert_eq!(report["injected_dropped"].as_u64(), Some(received), "every arrival dropped by the profile: {report}");
    let lost = report["lost"].as_u64().unwrap();
    assert!(received + lost <= sent, "only what was sent is counted: {report}, {sent} sent");
    assert!(objects.try_recv().is_none(), "nothing delivered");
}
