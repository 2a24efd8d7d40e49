//! `slipstream eval platoon` with the real binaries: a three-car platoon at two time gaps, its
//! figures read from the run (the leader's dip as scripted, every car's speeds recorded, the
//! ratios those figures give), the files it writes, a scenario that is no platoon refused; the
//! same with camera perception (a detector per car), with faults, through a router and on the
//! realtime clock.

use std::time::Duration;

use crate::common::{bin, run_with_limit, serial, temp_dir};

/// Three cars behind a leader that dips from 20 to 16 m/s at 1.5 m/s2 from t = 3 s.
const THREE: &str = r#"{ name: "three", duration_s: 14, road: { length_m: 3000 },
  egos: [ { namespace: "a", lane: 1, s_m: 300, speed_mps: 20, set_speed_mps: 25 },
          { namespace: "b", lane: 1, s_m: 250, speed_mps: 20, set_speed_mps: 25 },
          { namespace: "c", lane: 1, s_m: 200, speed_mps: 20, set_speed_mps: 25 } ],
  traffic: [ { lane: 1, gap_m: 40, speed_mps: 20, follow: false,
               actions: [ { at_s: 3, speed_mps: 16, accel_mps2: 1.5 } ] } ],
  variation: { gap_m: 0, speed_mps: 0 } }"#;

/// `slipstream eval platoon` on the three cars with `args` (and --json --report DIR/report):
/// its report, once it ran successfully.
fn eval_platoon(dir: &std::path::Path, args: &[&str]) -> serde_json::Value {
    std::fs::create_dir_all(dir).unwrap();
    let file = dir.join("three.json5");
    std::fs::write(&file, THREE).unwrap();
    let mut cmd = bin("slipstream");
    cmd.args(["eval", "platoon", "--scenario"]).arg(&file).args(args).args(["--json", "--report"]);
    cmd.arg(dir.join("report"));
    let out = run_with_limit(cmd, Duration::from_secs(300));
    assert!(out.status.success(), "stderr: {}", String::from_utf8_lossy(&out.stderr));
    serde_json::from_slice(&out.stdout).unwrap()
}

#[test]
fn a_platoon_is_measured_car_by_car_at_each_time_gap() {
    let _serial = serial();
    let dir = temp_dir("platoon");
    let r = eval_platoon(&dir, &["--time-gaps", "1.0,2.0"]);
    assert_eq!((r["cars"].as_u64(), r["disturbance_s"].as_f64()), (Some(3), Some(3.0)), "{r}");
    let runs = r["runs"].as_array().unwrap();
    assert_eq!(runs.len(), 2);
    for (run, gap) in runs.iter().zip([1.0, 2.0]) {
        assert_eq!(run["time_gap_s"].as_f64(), Some(gap));
        assert_eq!((run["collisions"].as_u64(), run["lockstep_timeouts"].as_u64()), (Some(0), Some(0)), "{run}");
        let cars = run["cars"].as_array().unwrap();
        let names: Vec<&str> = cars.iter().map(|c| c["car"].as_str().unwrap()).collect();
        assert_eq!(names, ["leader", "a", "b", "c"]);
        let peak = |k: usize| cars[k]["peak_speed_error_mps"].as_f64().unwrap();
        assert!((peak(0) - 4.0).abs() < 0.3, "the leader dips 4 m/s: {}", peak(0));
        for (k, car) in cars.iter().enumerate().skip(1) {
            assert!(peak(k) > 1.0, "car {k} follows the dip: {run}");
            let ratio = car["speed_ratio"].as_f64().unwrap();
            assert!((ratio - peak(k) / peak(k - 1)).abs() < 1e-9);
        }
        let largest = (1..4).map(|k| cars[k]["speed_ratio"].as_f64().unwrap()).fold(0.0, f64::max);
        assert_eq!(run["stable"].as_bool(), Some(largest <= 1.0));
    }
    let bound = r["bound_s"].as_f64().unwrap();
    assert!(bound > 0.0 && bound < 1.0, "2 x (one state period + a car's lag): {bound}");
    for f in ["platoon.json", "platoon.png", "gap-1/scenario.json5", "gap-2/sim.json", "gap-2/c-acc.log"] {
        assert!(dir.join("report").join(f).is_file(), "{f}");
    }

    let mut cmd = bin("slipstream");
    cmd.args(["eval", "platoon", "--scenario", "cut-in", "--report"]).arg(dir.join("not"));
    let out = run_with_limit(cmd, Duration::from_secs(60));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains("not a built-in platoon"), "{err}");
}

/// The same platoon with camera perception: each car's detector beside its ACC, the leader's
/// dip still read from the first car's ground truth, every car following it.
#[test]
fn a_platoon_on_camera_perception_runs_a_detector_per_car() {
    let _serial = serial();
    let dir = temp_dir("platoon-camera");
    let r = eval_platoon(&dir, &["--perception", "camera", "--time-gaps", "1.8"]);
    let run = &r["runs"][0];
    assert_eq!((run["collisions"].as_u64(), run["lockstep_timeouts"].as_u64()), (Some(0), Some(0)), "{run}");
    let cars = run["cars"].as_array().unwrap();
    let peak = |k: usize| cars[k]["peak_speed_error_mps"].as_f64().unwrap();
    assert!((peak(0) - 4.0).abs() < 0.3, "the leader dips 4 m/s: {}", peak(0));
    assert!((1..4).all(|k| peak(k) > 1.0), "every car follows the dip on its detections: {run}");
    for car in ["a", "b", "c"] {
        assert!(dir.join("report").join(format!("gap-1.8/{car}-detect.log")).is_file(), "car {car}'s detector log");
    }
}

/// `--faults`: every car's ACC and the simulator inject the profile on their own inputs; the
/// report names it; a profile lockstep cannot take is refused before anything runs.
#[test]
fn a_platoon_with_faults_on_every_cars_links_is_measured_and_says_so() {
    let _serial = serial();
    let dir = temp_dir("platoon-faults");
    let r = eval_platoon(&dir, &["--faults", "wifi-busy", "--time-gaps", "1.8"]);
    let file = dir.join("three.json5");
    assert!(r["faults"].as_str().is_some_and(|f| f.starts_with("wifi-busy")), "{r}");
    let run = &r["runs"][0];
    assert_eq!((run["collisions"].as_u64(), run["lockstep_timeouts"].as_u64()), (Some(0), Some(0)), "{run}");
    let sim: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("report/gap-1.8/sim.json")).unwrap()).unwrap();
    let control = &sim["control_input"];
    assert!(control["injected_delayed"].as_u64().unwrap() > 0, "the simulator delayed commands: {control}");
    for car in ["a", "b", "c"] {
        let log = std::fs::read_to_string(dir.join(format!("report/gap-1.8/{car}-acc.log"))).unwrap();
        assert!(log.contains("injecting faults"), "car {car}'s ACC injects: {log}");
    }

    let speed = dir.join("speed.json5");
    std::fs::write(&speed, r#"{ topics: { "vehicle/speed": { loss: 0.1 } } }"#).unwrap();
    let mut cmd = bin("slipstream");
    cmd.args(["eval", "platoon", "--faults"]).arg(&speed).args(["--scenario"]).arg(&file);
    cmd.arg("--report").arg(dir.join("refused"));
    let out = run_with_limit(cmd, Duration::from_secs(60));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains("cannot run in lockstep"), "{err}");
    assert!(!dir.join("refused/gap-0.8").exists(), "nothing ran");
}

/// `--router` alone: the runs start a `slipstream router` of their own and every node is its
/// client, so every car's messages cross it; lockstep makes the figures those of the direct
/// links, car by car, and the report names the router.
#[test]
fn a_platoon_through_a_router_measures_the_figures_of_the_direct_links() {
    let _serial = serial();
    let dir = temp_dir("platoon-router");
    let via = eval_platoon(&dir.join("via"), &["--router", "--time-gaps", "1.0"]);
    let direct = eval_platoon(&dir.join("direct"), &["--time-gaps", "1.0"]);
    assert!(via["router"].as_str().is_some_and(|r| r.starts_with("tcp/127.0.0.1:")), "{via}");
    assert!(direct["router"].is_null(), "{direct}");
    let peaks = |r: &serde_json::Value| -> Vec<(String, f64)> {
        let cars = r["runs"][0]["cars"].as_array().unwrap().iter();
        cars.map(|c| (c["car"].as_str().unwrap().to_string(), c["peak_speed_error_mps"].as_f64().unwrap())).collect()
    };
    let (v, d) = (peaks(&via), peaks(&direct));
    assert_eq!(v.len(), 4);
    for ((car, a), (_, b)) in v.iter().zip(&d) {
        assert!(a > &1.0 && (a - b).abs() < 1e-4, "{car}: {a} through the router, {b} direct");
    }
    let log = std::fs::read_to_string(dir.join("via/report/router.log")).unwrap();
    assert!(log.contains("router up"), "{log}");
}

/// `--mode realtime`: the simulator runs on the wall clock without waiting for the cars, so the
/// run measures the first car's loop latency, and the bound takes it as its delay.
#[test]
fn a_realtime_platoon_takes_the_measured_loop_latency_into_the_bound() {
    let _serial = serial();
    let dir = temp_dir("platoon-realtime");
    let r = eval_platoon(&dir, &["--mode", "realtime", "--time-gaps", "1.8"]);
    assert_eq!(r["clock"].as_str(), Some("realtime"), "{r}");
    let run = &r["runs"][0];
    assert_eq!(run["collisions"].as_u64(), Some(0), "{run}");
    let p99_ms = run["loop_p99_ms"].as_f64().expect("car 1's latency measured");
    let (delay, lag, bound) =
        (r["delay_s"].as_f64().unwrap(), r["actuator_lag_s"].as_f64().unwrap(), r["bound_s"].as_f64().unwrap());
    assert!(p99_ms > 0.0 && (delay - p99_ms / 1e3).abs() < 1e-9, "delay {delay} s, p99 {p99_ms} ms");
    assert!((bound - 2.0 * (delay + lag)).abs() < 1e-9, "{r}");
    let cars = run["cars"].as_array().unwrap();
    assert!(
        (1..4).all(|k| cars[k]["peak_speed_error_mps"].as_f64().unwrap() > 1.0),
        "every car follows the dip: {run}"
    );
    let sim = std::fs::read_to_string(dir.join("report/gap-1.8/sim.log")).unwrap();
    assert!(sim.contains("mode=Realtime"), "{sim}");
    let acc = std::fs::read_to_string(dir.join("report/gap-1.8/a-acc.log")).unwrap();
    assert!(acc.contains("lockstep=false"), "{acc}");
}
