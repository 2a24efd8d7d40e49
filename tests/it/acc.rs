//! slipstream-acc: the node over Zenoh (answers, stale inputs, a vanished detector), its
//! command line, and the scenario suite with every node a separate process.

use std::path::PathBuf;
use std::process::{Command, Output};
use std::time::{Duration, Instant};

use crate::common;
use slipstream::acc::node::AccStats;
use slipstream::acc::{AccSettings, PerceptionSource};
use slipstream::msg::{
    AccMode, AccStatus, AccWarning, BoundingBox2d, ControlCommand, Detection, Detections, EgoInfo, GroundTruthObject,
    GroundTruthObjects, ObjectClass, Speed, VehicleState,
};
use slipstream::{topics, Bus, TopicMap};

/// A loopback session pair: the ACC on one bus, the test's simulator stand-in on the other.
async fn acc_and_sim(
    settings: AccSettings,
) -> (tokio::task::JoinHandle<AccStats>, tokio::sync::oneshot::Sender<()>, Bus, String) {
    let (s1, ep) = common::listening_session().await;
    let s2 = common::connected_session(&ep).await;
    let acc_bus = Bus::from_session(s1, TopicMap::default(), "acc").await.unwrap();
    let sim_bus = Bus::from_session(s2, TopicMap::default(), "sim").await.unwrap();
    let (stop_tx, stop_rx) = tokio::sync::oneshot::channel::<()>();
    let task = tokio::spawn(async move {
        slipstream::acc::node::run(&acc_bus, settings, async {
            let _ = stop_rx.await;
        })
        .await
        .unwrap()
    });
    (task, stop_tx, sim_bus, ep)
}

fn state(step: u64, speed: f64) -> VehicleState {
    VehicleState {
        step,
        position_in_world_m: [0.0; 3],
        yaw_in_world_rad: 0.0,
        pitch_rad: 0.0,
        roll_rad: 0.0,
        velocity_in_world_mps: [speed, 0.0, 0.0],
        acceleration_in_body_mps2: [0.0; 3],
        yaw_rate_radps: 0.0,
        speed_mps: speed,
        lane: 1,
        applied: ControlCommand::NEUTRAL,
        control_timing: None,
    }
}

fn lead_truth(step: u64, gap_m: f64) -> GroundTruthObjects {
    GroundTruthObjects {
        step,
        objects: vec![GroundTruthObject {
            id: 1,
            class: ObjectClass::Car,
            size_m: [4.6, 1.85, 1.45],
            lane: 1,
            position_in_world_m: [0.0; 3],
            yaw_in_world_rad: 0.0,
            velocity_in_world_mps: [20.0, 0.0, 0.0],
            position_in_ego_m: [gap_m + 3.65, 0.0, 0.7],
            yaw_in_ego_rad: 0.0,
            velocity_in_ego_mps: [0.0, 0.0, 0.0],
            bbox: None,
            visible_fraction: 1.0,
            brake_lights: false,
        }],
    }
}

/// The test's stand-in simulator: publishes speed and state per step (and ground truth every
/// fifth step while `with_perception(step)`), paced at ~2 ms a step.
struct FakeSim {
    speed: slipstream::bus::Publisher<Speed>,
    state: slipstream::bus::Publisher<VehicleState>,
    objects: slipstream::bus::Publisher<GroundTruthObjects>,
    step: u64,
}

impl FakeSim {
    async fn new(bus: &Bus) -> Self {
        let speed = bus.publisher(topics::VEHICLE_SPEED).await.unwrap();
        let state = bus.publisher(topics::VEHICLE_STATE).await.unwrap();
        let objects = bus.publisher(topics::OBJECTS).await.unwrap();
        assert!(speed.wait_for_subscriber(common::TIMEOUT).await, "the ACC subscribes to vehicle/speed");
        FakeSim { speed, state, objects, step: 0 }
    }

    async fn run(&mut self, steps: u64, perception: bool) {
        for _ in 0..steps {
            let t_ns = self.step * 10_000_000;
            self.speed.put(t_ns, &Speed { speed_mps: 20.0 }).unwrap();
            self.state.put(t_ns, &state(self.step, 20.0)).unwrap();
            if perception && self.step.is_multiple_of(5) {
                self.objects.put(t_ns, &lead_truth(self.step, 40.0)).unwrap();
            }
            self.step += 1;
            tokio::time::sleep(Duration::from_millis(2)).await;
        }
    }

    /// `steps` steps without perception, each waiting for the ACC's answer, as a lockstep
    /// simulator does.
    async fn lockstep(&mut self, steps: u64, controls: &Collect<ControlCommand>) {
        for _ in 0..steps {
            let k = self.step;
            self.run(1, false).await;
            until(controls, answer_from(k)).await;
        }
    }
}

/// Everything a topic delivers, kept (a queued subscriber would keep only the newest few).
struct Collect<M> {
    _sub: slipstream::bus::CallbackSubscriber,
    got: std::sync::Arc<std::sync::Mutex<Vec<slipstream::bus::Received<M>>>>,
}

impl<M: slipstream::msg::Message + serde::de::DeserializeOwned + Clone + Send + 'static> Collect<M> {
    async fn new(bus: &Bus, topic: topics::TopicDef<M>) -> Self {
        let got = std::sync::Arc::new(std::sync::Mutex::new(Vec::new()));
        let into = got.clone();
        let _sub = bus.subscribe_with(topic, move |r| into.lock().unwrap().push(r)).await.unwrap();
        Collect { _sub, got }
    }
}

/// Takes everything received so far.
fn drain<M>(c: &Collect<M>) -> Vec<slipstream::bus::Received<M>> {
    std::mem::take(&mut *c.got.lock().unwrap())
}

fn truth_settings() -> AccSettings {
    AccSettings { perception: PerceptionSource::GroundTruth, set_speed_mps: 30.0, ..AccSettings::default() }
}

/// Waits until `done` holds for what `c` has collected (every await is under `within!`, so
/// a condition that never comes fails the test instead of hanging it).
async fn until<M>(c: &Collect<M>, done: impl Fn(&[slipstream::bus::Received<M>]) -> bool) {
    while !done(&c.got.lock().unwrap()) {
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
}

/// A status stamped at or after `t_ns` of simulated time has arrived.
fn status_from(t_ns: u64) -> impl Fn(&[slipstream::bus::Received<AccStatus>]) -> bool {
    move |got| got.iter().any(|s| s.header.stamp_sim_ns >= t_ns)
}

/// A command answering step `k` or a later one has arrived.
fn answer_from(k: u64) -> impl Fn(&[slipstream::bus::Received<ControlCommand>]) -> bool {
    move |got| got.iter().any(|c| c.msg.answers_step.is_some_and(|a| a >= k))
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn control_answers_each_step_and_stale_perception_brakes_smoothly_then_recovers() {
    within!(async {
        let (task, stop, sim_bus, _) = acc_and_sim(truth_settings()).await;
        let controls = Collect::new(&sim_bus, topics::VEHICLE_CONTROL).await;
        let statuses = Collect::new(&sim_bus, topics::ACC_STATUS).await;
        let mut sim = FakeSim::new(&sim_bus).await;

        // Fresh: following the lead 40 m ahead; every command answers the step of its speed
        // message and names the ACC. (Speed and control drop rather than queue under load, so
        // how many arrive is not the point here.)
        sim.run(200, true).await;
        until(&controls, answer_from(190)).await;
        until(&statuses, status_from(1_900_000_000)).await;
        let got = drain(&controls);
        for c in &got {
            assert_eq!(c.msg.answers_step, Some(c.header.stamp_sim_ns / 10_000_000), "answers the step of its speed");
            assert_eq!(c.source.as_deref(), Some("acc"), "attaches its node name");
        }
        let last: AccStatus = drain(&statuses).last().unwrap().msg.clone();
        assert_eq!(last.mode, AccMode::Follow);
        assert!(last.warnings.is_empty());
        assert_eq!(last.lead.unwrap().id, 1);

        // Perception stops (simulated time goes on): Stale after 400 ms, no throttle, braking.
        sim.run(150, false).await;
        until(&controls, answer_from(340)).await;
        until(&statuses, status_from(3_400_000_000)).await;
        let stale: Vec<_> = drain(&statuses).into_iter().filter(|s| s.msg.mode == AccMode::Stale).collect();
        assert!(!stale.is_empty(), "acc/status reports Stale");
        assert!(stale.iter().all(|s| s.msg.warnings.contains(&AccWarning::StalePerception)));
        let first_stale_ns = stale[0].header.stamp_sim_ns;
        let after: Vec<_> = drain(&controls).into_iter().filter(|c| c.header.stamp_sim_ns >= first_stale_ns).collect();
        assert!(after.iter().all(|c| c.msg.throttle == 0.0), "never accelerates on stale data");
        let brakes: Vec<f32> = after.iter().map(|c| c.msg.brake).collect();
        assert!(brakes.last().unwrap() > &0.05, "brakes: {brakes:?}");
        assert!(brakes.windows(2).all(|w| w[1] - w[0] < 0.05), "brakes smoothly, no jump: {brakes:?}");

        // Perception returns: control resumes.
        sim.run(100, true).await;
        until(&statuses, status_from(4_400_000_000)).await;
        let back = drain(&statuses).last().unwrap().msg.clone();
        assert_ne!(back.mode, AccMode::Stale, "{back:?}");
        assert!(back.warnings.is_empty());

        stop.send(()).unwrap();
        task.await.unwrap();
    });
}

/// Outside lockstep the answer to a speed message taken with a camera frame waits (at most
/// `perception_wait_ms`) for that frame's perception, so the command reacts to the frame at
/// once; with the wait off it answers with the perception it has.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_realtime_answer_waits_briefly_for_its_frames_perception() {
    within!(async {
        for wait_ms in [50, 0] {
            let settings = AccSettings { perception_wait_ms: wait_ms, ..truth_settings() };
            let (task, stop, sim_bus, _) = acc_and_sim(settings).await;
            let controls = Collect::new(&sim_bus, topics::VEHICLE_CONTROL).await;
            // Frames at 20 Hz (every fifth 100 Hz step), as camera/front/info says.
            let info_pub = sim_bus.publisher(topics::CAMERA_FRONT_INFO).await.unwrap();
            let info = slipstream::sim::SimSettings::default().camera_info(slipstream::msg::ImageEncoding::Rgb8);
            info_pub.put(0, &info).unwrap();
            let mut sim = FakeSim::new(&sim_bus).await;
            sim.run(10, true).await;
            until(&controls, answer_from(9)).await;
            drain(&controls);
            // Step 10 brings a frame: its speed and state first, its perception a little later
            // (as a detector's would).
            let t_ns = 10 * 10_000_000;
            sim.speed.put(t_ns, &Speed { speed_mps: 20.0 }).unwrap();
            sim.state.put(t_ns, &state(10, 20.0)).unwrap();
            if wait_ms == 0 {
                // Not waited for: the answer comes first, whenever the perception does.
                until(&controls, answer_from(10)).await;
            } else {
                tokio::time::sleep(Duration::from_millis(2)).await;
            }
            let perceived = sim.objects.put(t_ns, &lead_truth(10, 40.0)).unwrap().unwrap();
            until(&controls, answer_from(10)).await;
            let answer = drain(&controls).into_iter().find(|c| c.msg.answers_step == Some(10)).unwrap();
            let reacts_to_frame = answer.msg.perception_stamp_pub_ns == Some(perceived.stamp_pub_ns);
            assert_eq!(reacts_to_frame, wait_ms > 0, "perception_wait_ms {wait_ms}: {answer:?}");
            stop.send(()).unwrap();
            task.await.unwrap();
        }
    });
}

/// The watchdog over the bus: its timing is unit-tested on an injected clock (crates/acc/src/node.rs);
/// here, that its commands and status reach the simulator and stop when speed returns.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn stale_speed_makes_the_watchdog_brake_until_speed_returns() {
    within!(async {
        let (task, stop, sim_bus, _) = acc_and_sim(truth_settings()).await;
        let controls = Collect::new(&sim_bus, topics::VEHICLE_CONTROL).await;
        let statuses = Collect::new(&sim_bus, topics::ACC_STATUS).await;
        let mut sim = FakeSim::new(&sim_bus).await;
        sim.run(100, true).await;
        until(&controls, answer_from(90)).await;

        // No speed: the watchdog publishes braking commands that answer no step, and says why.
        until(&controls, |got| got.iter().filter(|c| c.msg.answers_step.is_none()).count() >= 3).await;
        until(&statuses, |got| got.last().is_some_and(|s| s.msg.warnings.contains(&AccWarning::StaleSpeed))).await;
        let watchdog: Vec<_> = drain(&controls).into_iter().filter(|c| c.msg.answers_step.is_none()).collect();
        assert!(watchdog.iter().all(|c| c.msg.throttle == 0.0));
        assert!(watchdog.last().unwrap().msg.brake > 0.0);
        let status = drain(&statuses).last().unwrap().msg.clone();
        assert_eq!(status.mode, AccMode::Stale);

        // Speed returns: answers again, no longer stale.
        sim.run(100, true).await;
        until(&controls, answer_from(190)).await;
        until(&statuses, status_from(1_900_000_000)).await;
        let status = drain(&statuses).last().unwrap().msg.clone();
        assert_ne!(status.mode, AccMode::Stale, "{status:?}");

        stop.send(()).unwrap();
        task.await.unwrap();
    });
}

/// A latched sim/ego as a simulator publishes it: a car, with the driver's settings given.
async fn publish_ego(
    sim_bus: &Bus,
    set_speed_mps: f64,
    time_gap_s: Option<f64>,
) -> slipstream::bus::Publisher<EgoInfo> {
    let ego = slipstream::vehicle::VehicleParams::CAR.ego_info(ObjectClass::Car, set_speed_mps, time_gap_s);
    let publisher = sim_bus.publisher(topics::SIM_EGO).await.unwrap();
    publisher.put(0, &ego).unwrap();
    publisher
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_acc_started_without_set_speed_flags_drives_the_scenarios_settings_from_sim_ego() {
    within!(async {
        // The settings' 30 m/s and 1.8 s, nothing given by a flag: sim/ego's 22 m/s and 2.4 s win.
        let (task, stop, sim_bus, _) = acc_and_sim(truth_settings()).await;
        let statuses = Collect::new(&sim_bus, topics::ACC_STATUS).await;
        let _ego = publish_ego(&sim_bus, 22.0, Some(2.4)).await;
        let mut sim = FakeSim::new(&sim_bus).await;
        sim.run(100, true).await;
        until(&statuses, |got| got.last().is_some_and(|s| s.msg.set_speed_mps == 22.0)).await;
        assert_eq!(drain(&statuses).last().unwrap().msg.time_gap_s, 2.4);
        stop.send(()).unwrap();
        task.await.unwrap();

        // --set-speed given: it stands; the time gap no flag gave still comes from sim/ego.
        let mut flagged = truth_settings();
        flagged.from_scenario.set_speed = false;
        let (task, stop, sim_bus, _) = acc_and_sim(flagged).await;
        let statuses = Collect::new(&sim_bus, topics::ACC_STATUS).await;
        let _ego = publish_ego(&sim_bus, 22.0, Some(2.4)).await;
        let mut sim = FakeSim::new(&sim_bus).await;
        sim.run(100, true).await;
        until(&statuses, |got| got.last().is_some_and(|s| s.msg.time_gap_s == 2.4)).await;
        assert_eq!(drain(&statuses).last().unwrap().msg.set_speed_mps, 30.0);
        stop.send(()).unwrap();
        task.await.unwrap();
    });
}

/// In lockstep the simulator waits for the ACC: speed late by the wall clock (a loaded
/// machine, a simulator paused) is no stale input, and no watchdog command may step the
/// controller between two answers (that made two runs of one scenario differ).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_lockstep_acc_sends_no_watchdog_commands_while_the_simulator_pauses() {
    within!(async {
        let settings = AccSettings { lockstep: true, ..truth_settings() };
        let max_age = Duration::from_millis(settings.stale.speed_max_age_ms);
        let (task, stop, sim_bus, _) = acc_and_sim(settings).await;
        let controls = Collect::new(&sim_bus, topics::VEHICLE_CONTROL).await;
        let statuses = Collect::new(&sim_bus, topics::ACC_STATUS).await;
        let mut sim = FakeSim::new(&sim_bus).await;
        sim.run(100, true).await;
        until(&controls, answer_from(90)).await;
        tokio::time::sleep(max_age * 4).await;
        sim.run(100, true).await;
        until(&controls, answer_from(190)).await;
        let unanswered = drain(&controls).iter().filter(|c| c.msg.answers_step.is_none()).count();
        assert_eq!(unanswered, 0, "commands answering no step in lockstep");
        let stale = drain(&statuses).iter().filter(|s| s.msg.warnings.contains(&AccWarning::StaleSpeed)).count();
        assert_eq!(stale, 0, "StaleSpeed in lockstep");
        stop.send(()).unwrap();
        task.await.unwrap();
    });
}

/// A detector node of its own dialling the ACC at `ep` (its perception/objects publisher,
/// matched by the ACC), and camera/front/info at 20 Hz (every fifth step) from the simulator's
/// bus, so the ACC knows which steps bring a frame.
async fn detector_and_camera_info(ep: &str, sim_bus: &Bus) -> (Bus, slipstream::bus::Publisher<Detections>) {
    let detect_bus =
        Bus::from_session(common::connected_session(ep).await, TopicMap::default(), "detect").await.unwrap();
    let detections = detect_bus.publisher(topics::PERCEPTION_OBJECTS).await.unwrap();
    assert!(detections.wait_for_subscriber(common::TIMEOUT).await);
    let info_pub = sim_bus.publisher(topics::CAMERA_FRONT_INFO).await.unwrap();
    let info = slipstream::sim::SimSettings::default().camera_info(slipstream::msg::ImageEncoding::Rgb8);
    info_pub.put(0, &info).unwrap();
    (detect_bus, detections)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_vanished_detector_is_perception_lost() {
    within!(async {
        let settings = AccSettings { perception: PerceptionSource::Camera, ..truth_settings() };
        let (task, stop, sim_bus, ep) = acc_and_sim(settings).await;
        let statuses = Collect::new(&sim_bus, topics::ACC_STATUS).await;
        // The detector: a node of its own, publishing detections of the lead.
        let (detect_bus, detections) = detector_and_camera_info(&ep, &sim_bus).await;
        let mut sim = FakeSim::new(&sim_bus).await;
        let detect_step = |step: u64| Detections {
            frame_seq: step / 5,
            frame_stamp_pub_ns: 0,
            detections: vec![Detection {
                track_id: 4,
                class: ObjectClass::Car,
                bbox: BoundingBox2d { u_min_px: 300.0, v_min_px: 220.0, u_max_px: 340.0, v_max_px: 250.0 },
                confidence: 0.9,
                distance_m: 43.65,
                lateral_offset_m: 0.1,
                relative_speed_mps: 0.0,
                distance_sigma_m: 0.2,
                relative_speed_sigma_mps: 0.3,
                brake_lights: false,
            }],
        };
        for _ in 0..40 {
            let k = sim.step;
            detections.put(k * 10_000_000, &detect_step(k)).unwrap();
            sim.run(5, false).await;
        }
        until(&statuses, status_from(1_900_000_000)).await;
        let status = drain(&statuses).last().unwrap().msg.clone();
        assert_eq!(status.mode, AccMode::Follow, "{status:?}");
        assert_eq!(status.lead.unwrap().id, 4);

        // The detector's process ends: its liveliness token goes, the ACC says so at once.
        detect_bus.close().await.unwrap();
        let deadline = Instant::now() + Duration::from_secs(10);
        let mut frame_steps_until_lost = 0;
        loop {
            sim.run(10, false).await;
            frame_steps_until_lost += 2;
            let lost = drain(&statuses).iter().any(|s| s.msg.warnings.contains(&AccWarning::PerceptionLost));
            if lost {
                break;
            }
            assert!(Instant::now() < deadline, "no PerceptionLost within 10 s");
        }
        // From then on a frame step's answer does not wait for perception that cannot come.
        sim.run(100, false).await;

        stop.send(()).unwrap();
        let stats = task.await.unwrap();
        assert!(
            stats.perception_waits_timed_out <= frame_steps_until_lost + 4,
            "{} waits ran out; {frame_steps_until_lost} frame steps came before the detector was known gone (20 after)",
            stats.perception_waits_timed_out
        );
    });
}

/// In lockstep each frame step's answer waits for that frame's perception, but a detector that
/// publishes nothing (alive, without camera info or stuck) costs one wait, not one per frame:
/// the run goes on instead of crawling at lockstep_wait_ms a frame. Waiting resumes once
/// perception comes again.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_lockstep_acc_stops_waiting_for_a_detector_that_sends_nothing() {
    within!(async {
        let settings = AccSettings {
            perception: PerceptionSource::Camera,
            lockstep: true,
            lockstep_wait_ms: 300,
            ..truth_settings()
        };
        let (task, stop, sim_bus, ep) = acc_and_sim(settings).await;
        let controls = Collect::new(&sim_bus, topics::VEHICLE_CONTROL).await;
        // The detector: alive on the bus, silent until told.
        let (_detect_bus, detections) = detector_and_camera_info(&ep, &sim_bus).await;
        let mut sim = FakeSim::new(&sim_bus).await;
        // A lockstep simulator: each step waits for its answer. 50 steps bring 10 frames.
        sim.lockstep(50, &controls).await;
        // Perception comes again (for the frame at this step), then stops again.
        let k = sim.step;
        let empty = Detections { frame_seq: k / 5, frame_stamp_pub_ns: 0, detections: vec![] };
        detections.put(k * 10_000_000, &empty).unwrap();
        sim.lockstep(50, &controls).await;
        stop.send(()).unwrap();
        let stats = task.await.unwrap();
        assert_eq!(
            stats.lockstep_waits_timed_out, 2,
            "one wait ran out before each silence was known, of 20 frame steps without perception"
        );
        assert_eq!(stats.perception_frames, 1);
    });
}

fn acc_bin() -> Command {
    common::bin("slipstream-acc")
}

fn run(cmd: Command, limit: Duration) -> Output {
    common::run_with_limit(cmd, limit)
}

#[test]
fn bad_settings_fail_with_file_key_and_fix() {
    let dir = std::env::temp_dir().join(format!("slipstream-acc-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join("acc.json5");
    std::fs::write(&file, "{ limits: { jerk_mps3: -1 } }").unwrap();
    let out = run(
        {
            let mut c = acc_bin();
            c.arg("--settings").arg(&file);
            c
        },
        Duration::from_secs(30),
    );
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("acc.json5") && err.contains("limits.jerk_mps3") && err.contains("fix"), "{err}");
    assert!(out.stdout.is_empty(), "no report without --json");

    // With --json (as `up` and `eval` run it), the failure is the node's report on stdout.
    let out = run(
        {
            let mut c = acc_bin();
            c.arg("--settings").arg(&file).arg("--json");
            c
        },
        Duration::from_secs(30),
    );
    assert!(!out.status.success());
    let failure = slipstream::node::Failure::in_report(&out.stdout)
        .unwrap_or_else(|| panic!("no failure report: {}", String::from_utf8_lossy(&out.stdout)));
    assert!(failure.line().contains("limits.jerk_mps3") && failure.line().contains("acc.json5"), "{failure:?}");

    let out = run(
        {
            let mut c = acc_bin();
            c.args(["--time-gap", "0.3"]);
            c
        },
        Duration::from_secs(30),
    );
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("time_gap_s") && err.contains("0.8"), "{err}");
}

/// The ACC drives the vehicle the scenario gives the ego: a truck (12 t, 6.5 m/s2 brakes,
/// 0.5 s lag, its front 7.3 m ahead of the rear axle) following a car that brakes to a stop
/// stops behind it. Driven as the default car (3.65 m), it took the gap for 3.65 m longer than
/// it was and ran into the car; a motorcycle ego driven as a car accelerated at 5 m/s2.
#[test]
fn eval_acc_drives_the_vehicle_its_scenario_gives_the_ego() {
    let _serial = common::serial();
    let dir = std::env::temp_dir().join(format!("slipstream-ego-class-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    for class in ["truck", "motorcycle"] {
        let file = dir.join(format!("ego-{class}.json5"));
        std::fs::write(
            &file,
            format!(
                r#"{{ name: "ego-{class}", duration_s: 35, seed: 5,
  ego: {{ lane: 1, speed_mps: 25, set_speed_mps: 27, class: "{class}" }},
  traffic: [ {{ lane: 1, gap_m: 50, speed_mps: 25, actions: [ {{ at_s: 12, speed_mps: 0, accel_mps2: 4 }} ] }} ],
  expect: {{ min_gap_m: 3 }} }}"#
            ),
        )
        .unwrap();
        let mut c = common::bin("slipstream");
        c.args(["eval", "acc", "--json", "--perception", "ground-truth", "--scenario"]).arg(&file);
        let out = run(c, Duration::from_secs(300));
        let report: serde_json::Value = serde_json::from_slice(&out.stdout)
            .unwrap_or_else(|e| panic!("{class}: {e}: {}", String::from_utf8_lossy(&out.stderr)));
        let m = &report["results"][0]["metrics"];
        assert_eq!(m["collisions"], 0, "{class}: {m}");
        assert!(m["min_gap_m"].as_f64().unwrap() >= 3.0, "{class}: {m}");
        assert!(m["pass"].as_bool().unwrap(), "{class}: {}", m["checks"]);
    }
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn eval_acc_runs_every_scenario_as_separate_processes_without_a_collision() {
    let _serial = common::serial();
    let plots = std::env::temp_dir().join(format!("slipstream-acc-plots-{}", std::process::id()));
    for perception in ["ground-truth", "camera"] {
        let mut c = common::bin("slipstream");
        c.args(["eval", "acc", "--json", "--perception", perception, "--plots"]).arg(&plots);
        let out = run(c, Duration::from_secs(900));
        let stdout = String::from_utf8_lossy(&out.stdout);
        let report: serde_json::Value = serde_json::from_str(&stdout)
            .unwrap_or_else(|e| panic!("{perception}: {e}: {stdout}\n{}", String::from_utf8_lossy(&out.stderr)));
        let results = report["results"].as_array().unwrap();
        assert_eq!(results.len(), slipstream::sim::scenario::BUILT_IN.len());
        assert!(report["jobs"].as_u64().is_some_and(|j| j >= 1), "{}", report["jobs"]);
        for r in results {
            let name = r["scenario"].as_str().unwrap();
            // Where the run's time went: the simulator's shares fit in its own run, which fits
            // in the whole run; the detector worked only with the camera.
            let t = &r["time"];
            let f = |v: &serde_json::Value| v.as_f64().unwrap();
            let shares: f64 =
                ["physics_s", "render_s", "publish_s", "awaiting_s", "pacing_s"].iter().map(|k| f(&t["sim"][k])).sum();
            assert!(f(&t["sim"]["physics_s"]) > 0.0 && f(&t["sim"]["render_s"]) > 0.0, "{name}: {t}");
            assert!(
                shares <= f(&t["sim_wall_s"]) * 1.01 + 0.01 && f(&t["sim_wall_s"]) <= f(&t["wall_s"]),
                "{name}: {t}"
            );
            assert_eq!(f(&t["detect_busy_s"]) > 0.0, perception == "camera", "{name}: {t}");
            let m = &r["metrics"];
            assert_eq!(m["collisions"], 0, "{perception} {name}: collision");
            assert_eq!(r["lockstep_timeouts"], 0, "{perception} {name}: lockstep timeouts");
            assert!(m["pass"].as_bool().unwrap(), "{perception} {name}: {}", m["checks"]);
            let png: PathBuf = r["plot"].as_str().unwrap().into();
            let img = image::open(&png).unwrap_or_else(|e| panic!("{}: {e}", png.display()));
            assert_eq!((img.width(), img.height()), (1100, 900));
        }
        assert!(out.status.success(), "{perception}: {}", String::from_utf8_lossy(&out.stderr));
        // The aims that must hold somewhere: steady following was judged, and speed mode.
        assert!(results.iter().any(|r| r["metrics"]["time_gap_rms_error_s"].as_f64().is_some_and(|e| e <= 0.1)));
        assert!(results.iter().any(|r| r["metrics"]["speed_rmse_mps"].as_f64().is_some()));
    }
    let _ = std::fs::remove_dir_all(&plots);
}

/// Two controllers started by hand under one name in one namespace, meeting as the default
/// config has nodes on one machine meet: the second says that the name is taken and how to
/// mend it; the first, alone when it started, says nothing of it.
#[tokio::test(flavor = "multi_thread")]
async fn a_second_node_under_a_taken_name_says_so() {
    let _one = common::serial();
    // The default config's way to meet on one machine, on a rendezvous of the test's own.
    let rendezvous = common::ep(common::free_port());
    let config = common::temp_dir("namesake").join("zenoh.json5");
    std::fs::write(&config, slipstream::config::DEFAULT_ZENOH_CONFIG.replace("tcp/127.0.0.1:7447", &rendezvous))
        .unwrap();
    let session = common::connected_session(&rendezvous).await;
    let start = || {
        let mut c = acc_bin();
        c.args(["--perception", "ground-truth", "-c"])
            .arg(&config)
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::piped());
        c.spawn().unwrap()
    };
    let mut first = start();
    let deadline = Instant::now() + Duration::from_secs(30);
    while session.liveliness().get("nodes/acc").await.unwrap().recv_async().await.is_err() {
        if Instant::now() > deadline {
            let _ = first.kill();
            let out = first.wait_with_output().unwrap();
            panic!("the first controller never declared nodes/acc: {}", String::from_utf8_lossy(&out.stderr));
        }
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    let mut second = start();
    let said = first_line_with(second.stderr.take().unwrap(), "another node named acc", Duration::from_secs(30));
    for child in [&mut first, &mut second] {
        let _ = child.kill();
        let _ = child.wait();
    }
    let said = said.expect("the second controller did not say its name was taken");
    assert!(said.contains("--name NAME") && said.contains("root namespace"), "{said}");
    let mut first_err = String::new();
    std::io::Read::read_to_string(&mut first.stderr.take().unwrap(), &mut first_err).unwrap();
    assert!(!first_err.contains("another node named"), "the first controller was alone: {first_err}");
}

/// The first line of `stream` containing `needle`, read for at most `limit` (in a thread, so
/// a quiet process cannot hold the test).
fn first_line_with(stream: impl std::io::Read + Send + 'static, needle: &str, limit: Duration) -> Option<String> {
    let (tx, rx) = std::sync::mpsc::channel();
    let needle = needle.to_string();
    std::thread::spawn(move || {
        for line in std::io::BufRead::lines(std::io::BufReader::new(stream)).map_while(Result::ok) {
            if line.contains(&needle) {
                let _ = tx.send(line);
                return;
            }
        }
    });
    rx.recv_timeout(limit).ok()
}
