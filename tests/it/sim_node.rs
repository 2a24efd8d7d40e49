//! The simulator on the bus: every topic at its rate to another process, lockstep
//! determinism, lockstep timeouts, collisions on sim/events, and the binary's errors.

use std::collections::BTreeMap;
use std::process::{Command, Stdio};
use std::sync::Arc;
use std::time::{Duration, Instant};

use parking_lot::Mutex;
use slipstream::msg::{self, ControlCommand, MessageKind, SimClock, SimEvent, SimEventKind};
use slipstream::sim::settings::{Mode, OnTimeout, SimSettings};
use slipstream::sim::{Scenario, World};
use slipstream::{topics, Bus, TopicMap};

use crate::common::{connected_session, listening_session, Killed};

/// Every sim topic reliable and blocking, so a recorder sees every message.
fn lossless_map() -> TopicMap {
    lossless_map_with("")
}

fn lossless_map_with(extra: &str) -> TopicMap {
    let entry = |name: &str| format!("\"{name}\": {{ congestion_control: \"block\", delivery: {{ queue: 4096 }} }}");
    let names = [
        "vehicle/speed",
        "vehicle/state",
        "vehicle/control",
        "camera/front",
        "camera/narrow",
        "objects",
        "sim/clock",
        "sim/events",
    ];
    let body = names.iter().map(|n| entry(n)).collect::<Vec<_>>().join(", ");
    TopicMap::from_json5(&format!("{{ {extra} topics: {{ {body} }} }}"), "test").unwrap()
}

/// The worlds of these tests step at 100 Hz: speed, state and clock every step.
pub(crate) fn settings(mode: Mode, wait_for: &[&str]) -> SimSettings {
    let mut s = SimSettings { mode, physics_hz: 100, ..SimSettings::default() };
    s.camera.width = 160;
    s.camera.height = 120;
    s.lockstep.wait_for = wait_for.iter().map(|s| s.to_string()).collect();
    s.lockstep.start_timeout_ms = 10_000;
    s
}

fn scenario(name: &str, duration_s: f64) -> Scenario {
    let mut s = Scenario::find(name).unwrap();
    s.duration_s = duration_s;
    s
}

/// Records every sample the simulator publishes, in arrival order per key.
/// (key, payload) in arrival order.
type Samples = Arc<Mutex<Vec<(String, Vec<u8>)>>>;

struct Recorder {
    samples: Samples,
    _subs: Vec<zenoh::pubsub::Subscriber<()>>,
}

impl Recorder {
    async fn new(session: &zenoh::Session, map: &TopicMap) -> Recorder {
        let samples = Arc::new(Mutex::new(Vec::new()));
        let mut subs = Vec::new();
        for t in [
            topics::VEHICLE_SPEED.topic,
            topics::VEHICLE_STATE.topic,
            topics::SIM_CLOCK.topic,
            topics::SIM_EVENTS.topic,
            topics::OBJECTS.topic,
            topics::CAMERA_FRONT.topic,
            topics::CAMERA_FRONT_INFO.topic,
            topics::CAMERA_NARROW.topic,
        ] {
            let samples = samples.clone();
            let sub = session
                .declare_subscriber(map.key(t))
                .callback(move |s: zenoh::sample::Sample| {
                    samples.lock().push((s.key_expr().to_string(), s.payload().to_bytes().into_owned()));
                })
                .await
                .unwrap();
            subs.push(sub);
        }
        Recorder { samples, _subs: subs }
    }

    fn events(&self) -> Vec<SimEvent> {
        self.samples
            .lock()
            .iter()
            .filter(|(k, _)| k.ends_with("sim/events"))
            .map(|(_, b)| msg::decode::<SimEvent>(b).unwrap().msg)
            .collect()
    }

    async fn wait_for_end(&self) {
        within!(async {
            while !self.events().iter().any(|e| matches!(e.kind, SimEventKind::ScenarioEnd { .. })) {
                tokio::time::sleep(Duration::from_millis(20)).await;
            }
        });
    }

    /// The stream with its two wall-clock fields taken out (each header's stamp_pub_ns and
    /// the clock's measured real-time factor): what must be identical between runs.
    fn deterministic_part(&self) -> BTreeMap<String, Vec<String>> {
        let mut by_key: BTreeMap<String, Vec<String>> = BTreeMap::new();
        for (key, bytes) in self.samples.lock().iter() {
            let kind = MessageKind::from_u8(bytes[1]).unwrap();
            let (header, body_start) = msg::decode_header(bytes, kind).unwrap();
            // Wall-clock fields (the real-time factor, the control's timing) differ run to run.
            let body = if kind == MessageKind::SimClock {
                let clock = SimClock { real_time_factor: 0.0, ..msg::decode::<SimClock>(bytes).unwrap().msg };
                format!("{clock:?}")
            } else if kind == MessageKind::VehicleState {
                let state = msg::decode::<msg::VehicleState>(bytes).unwrap().msg;
                assert!(state.step == 0 || state.control_timing.is_some(), "a command is in effect");
                let mut applied = state.applied;
                applied.perception_stamp_pub_ns = None;
                format!("{:?}", msg::VehicleState { control_timing: None, applied, ..state })
            } else {
                msg::hex_lines(&bytes[body_start..])
            };
            by_key.entry(key.clone()).or_default().push(format!("{} {} {}", header.seq, header.stamp_sim_ns, body));
        }
        by_key
    }
}

/// A deterministic controller: answers every vehicle/state with a speed-holding command.
async fn controller(bus: Bus, answer_until_step: u64) -> tokio::task::JoinHandle<()> {
    answering(bus, answer_until_step, |state| {
        let error = 22.0 - state.speed_mps;
        ControlCommand {
            throttle: (0.3 * error).clamp(0.0, 1.0) as f32,
            brake: (-0.3 * error).clamp(0.0, 1.0) as f32,
            ..ControlCommand::NEUTRAL
        }
    })
    .await
}

/// A controller on `bus` answering each vehicle/state before step `until_step` with `law`'s
/// command for it (its `answers_step` set to the state's step).
pub(crate) async fn answering(
    bus: Bus,
    until_step: u64,
    law: impl Fn(&msg::VehicleState) -> ControlCommand + Send + 'static,
) -> tokio::task::JoinHandle<()> {
    let states = bus.subscriber(topics::VEHICLE_STATE).await.unwrap();
    let control = bus.publisher(topics::VEHICLE_CONTROL).await.unwrap();
    tokio::spawn(async move {
        let _alive = bus;
        loop {
            let r = states.recv().await;
            if r.msg.step < until_step {
                let cmd = ControlCommand { answers_step: Some(r.msg.step), ..law(&r.msg) };
                control.put(r.header.stamp_sim_ns, &cmd).unwrap();
            }
        }
    })
}

/// One lockstep run of `scenario` with a controller; returns the recorded stream.
async fn lockstep_run(scenario_name: &str, seed: u64) -> BTreeMap<String, Vec<String>> {
    let map = lossless_map();
    let (s_sim, ep) = listening_session().await;
    let s_ctl = connected_session(&ep).await;
    let s_rec = connected_session(&ep).await;
    let recorder = Recorder::new(&s_rec, &map).await;
    let ctl = controller(Bus::from_session(s_ctl, map.clone(), "ctl").await.unwrap(), u64::MAX).await;
    let sim = Bus::from_session(s_sim, map, "sim").await.unwrap();
    let world = World::new(scenario(scenario_name, 3.0), seed, 100);
    let report =
        within!(slipstream::sim::run(&sim, world, &settings(Mode::Lockstep, &["ctl"]), std::future::pending()))
            .unwrap();
    assert_eq!((report.steps, report.lockstep_timeouts), (300, 0), "{report:?}");
    recorder.wait_for_end().await;
    // Frames go at a lower priority than sim/events: on a loaded machine the end overtakes
    // the last of them. Every frame the simulator sent arrives (blocking congestion control).
    within!(async {
        let count = |key: &str| recorder.samples.lock().iter().filter(|(k, _)| k.ends_with(key)).count();
        while count("camera/front") < report.frames as usize || count("camera/narrow") < report.frames as usize {
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
    });
    ctl.abort();
    // The controller's answer to step k is what the ego applied in step k -> k + 1.
    let states: Vec<msg::VehicleState> = recorder
        .samples
        .lock()
        .iter()
        .filter(|(k, _)| k == "vehicle/state")
        .map(|(_, b)| msg::decode::<msg::VehicleState>(b).unwrap().msg)
        .collect();
    assert!(states.iter().skip(1).all(|s| s.applied.answers_step == Some(s.step - 1)), "{:?}", &states[..3]);
    recorder.deterministic_part()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn lockstep_same_scenario_and_seed_give_identical_streams() {
    let first = lockstep_run("cut-in", 5).await;
    let second = lockstep_run("cut-in", 5).await;
    for (key, n) in
        [("vehicle/speed", 300), ("vehicle/state", 300), ("sim/clock", 300), ("camera/front", 60), ("objects", 60)]
    {
        assert_eq!(first.get(key).map(Vec::len), Some(n), "{key} in run 1");
    }
    assert_eq!(first.keys().collect::<Vec<_>>(), second.keys().collect::<Vec<_>>());
    for (key, a) in &first {
        let b = &second[key];
        assert_eq!(a.len(), b.len(), "{key}: message counts differ");
        if let Some(i) = (0..a.len()).find(|i| a[*i] != b[*i]) {
            panic!("{key}: message {i} differs between two runs with the same seed:\n{}\n{}", a[i], b[i]);
        }
    }
    let other_seed = lockstep_run("cut-in", 6).await;
    assert_ne!(first["objects"], other_seed["objects"], "another seed, another run");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn lockstep_names_a_late_controller_and_stops_when_told() {
    let map = lossless_map();
    let (s_sim, ep) = listening_session().await;
    let s_ctl = connected_session(&ep).await;
    let s_rec = connected_session(&ep).await;
    let recorder = Recorder::new(&s_rec, &map).await;
    let ctl = controller(Bus::from_session(s_ctl, map.clone(), "ctl").await.unwrap(), 50).await;
    let sim = Bus::from_session(s_sim, map.clone(), "sim").await.unwrap();
    let mut s = settings(Mode::Lockstep, &["ctl"]);
    s.lockstep.step_timeout_ms = 300;
    s.lockstep.on_timeout = OnTimeout::Stop;
    let world = World::new(scenario("steady-follow", 10.0), 1, 100);
    let report = within!(slipstream::sim::run(&sim, world, &s, std::future::pending())).unwrap();
    assert_eq!(report.steps, 50, "stops at the first unanswered step: {report:?}");
    let end = report.end.expect("ended");
    assert!(!end.success && end.reason.contains("lockstep timeout at step 50 waiting for ctl"), "{end:?}");
    recorder.wait_for_end().await;
    let late: Vec<_> = recorder
        .events()
        .into_iter()
        .filter_map(|e| match e.kind {
            SimEventKind::ControlTimeout { late } => Some(late),
            _ => None,
        })
        .collect();
    assert_eq!(late, vec![vec!["ctl".to_string()]]);
    ctl.abort();

    // A controller that never comes up: a clear error after the start timeout.
    let mut s = settings(Mode::Lockstep, &["ghost"]);
    s.lockstep.start_timeout_ms = 300;
    let world = World::new(scenario("steady-follow", 1.0), 1, 100);
    let err = within!(slipstream::sim::run(&sim, world, &s, std::future::pending())).unwrap_err();
    assert!(err.to_string().contains("ghost not up after 300 ms"), "{err}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn a_world_stepping_at_another_rate_than_the_settings_is_refused() {
    let (s_sim, _ep) = listening_session().await;
    let sim = Bus::from_session(s_sim, lossless_map(), "sim").await.unwrap();
    let s = SimSettings { mode: Mode::Fast, ..SimSettings::default() };
    let world = World::new(scenario("steady-follow", 1.0), 1, s.physics_hz / 5);
    let err = within!(slipstream::sim::run(&sim, world, &s, std::future::pending())).unwrap_err();
    let msg = err.to_string();
    assert!(msg.contains(&format!("{} Hz", s.physics_hz / 5)) && msg.contains("physics_hz"), "{msg}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn a_collision_is_published_on_sim_events_and_ends_the_run() {
    let map = lossless_map();
    let (s_sim, ep) = listening_session().await;
    let s_rec = connected_session(&ep).await;
    let recorder = Recorder::new(&s_rec, &map).await;
    let sim = Bus::from_session(s_sim, map, "sim").await.unwrap();
    let crash = Scenario::parse(
        "{ name: 'crash', duration_s: 30, ego: { lane: 1, speed_mps: 15 }, traffic: [ { lane: 1, gap_m: 30, speed_mps: 0 } ] }",
        "test",
    )
    .unwrap();
    let report = within!(slipstream::sim::run(
        &sim,
        World::new(crash, 1, 100),
        &settings(Mode::Fast, &[]),
        std::future::pending()
    ))
    .unwrap();
    assert_eq!(report.ego_collisions, 1);
    recorder.wait_for_end().await;
    let events = recorder.events();
    let collision = events.iter().find_map(|e| match &e.kind {
        SimEventKind::Collision { other_id, relative_speed_mps } => Some((*other_id, *relative_speed_mps)),
        _ => None,
    });
    let (other, speed) = collision.expect("a collision event");
    assert!(other == 1 && speed > 10.0, "{events:?}");
    assert!(matches!(&events.last().unwrap().kind, SimEventKind::ScenarioEnd { success: false, .. }), "{events:?}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn jpeg_frames_when_configured_and_malformed_control_is_counted_not_applied() {
    let map = lossless_map_with("camera: { encoding: \"jpeg\", jpeg_quality: 80 },");
    let (s_sim, ep) = listening_session().await;
    let s_rec = connected_session(&ep).await;
    let recorder = Recorder::new(&s_rec, &map).await;
    let control_key = map.key(topics::VEHICLE_CONTROL.topic);
    let spam = tokio::spawn(async move {
        for i in 0u32..400 {
            let junk: Vec<u8> = if i % 2 == 0 { vec![1, 3, 0xff] } else { vec![9; 40] };
            s_rec.put(&control_key, junk).await.unwrap();
            tokio::time::sleep(Duration::from_millis(5)).await;
        }
        s_rec
    });
    let sim = Bus::from_session(s_sim, map, "sim").await.unwrap();
    let world = World::new(scenario("steady-follow", 1.5), 1, 100);
    let report =
        within!(slipstream::sim::run(&sim, world, &settings(Mode::Realtime, &[]), std::future::pending())).unwrap();
    let _session = within!(spam).unwrap();
    assert!(report.control_rejected > 0, "{report:?}");
    assert_eq!(report.control_timeouts, 0, "garbage is not a command: the ego cruised on");
    assert!(report.end.as_ref().is_some_and(|e| e.success), "{report:?}");
    recorder.wait_for_end().await;
    let samples = recorder.samples.lock().clone();
    let frame_bytes = samples.iter().find(|(k, _)| k == "camera/front").map(|(_, b)| b.clone()).expect("a frame");
    let frame = msg::decode::<msg::CameraFrameRef>(&frame_bytes).unwrap().msg;
    assert_eq!((frame.encoding, frame.width, frame.height), (msg::ImageEncoding::Jpeg, 160, 120));
    assert!(frame.data.len() < 160 * 120 * 3 / 4, "compressed: {} bytes", frame.data.len());
    assert_eq!(frame.to_rgb8().unwrap().len(), 160 * 120 * 3);
    let info = samples
        .iter()
        .find(|(k, _)| k == "camera/front/info")
        .map(|(_, b)| msg::decode::<msg::CameraInfo>(b).unwrap().msg);
    assert_eq!(info.map(|i| i.encoding), Some(msg::ImageEncoding::Jpeg));
}

fn sim_bin() -> Command {
    crate::common::bin("slipstream-sim")
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
// The serial lock is held for the whole test on purpose: it keeps whole-loop tests apart.
#[allow(clippy::await_holding_lock)]
async fn another_process_receives_every_topic_at_its_rate() {
    let _serial = crate::common::serial();
    let (session, ep) = listening_session().await;
    let map = TopicMap::default();
    let recorder = Recorder::new(&session, &map).await;
    let bus = Bus::from_session(session, map, "watcher").await.unwrap();
    let started = Instant::now();
    let child = sim_bin()
        .args(["--scenario", "cut-in", "--duration", "4", "-e", &ep, "-l", "tcp/127.0.0.1:0"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let _child = Killed(child);
    // camera/front/info is latched: a subscriber that starts while the sim runs, long after
    // the info was published, still gets it.
    within!(async {
        while !recorder.samples.lock().iter().any(|(k, _)| k == "sim/clock") {
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
    });
    tokio::time::sleep(Duration::from_secs(1)).await;
    let late = bus.subscriber(topics::CAMERA_FRONT_INFO).await.unwrap();
    let info = within!(late.recv()).msg;
    assert_eq!((info.width, info.height, info.rate_hz), (640, 480, 20.0));
    recorder.wait_for_end().await;
    let wall_s = started.elapsed().as_secs_f64();

    let stamps = |key: &str| -> Vec<u64> {
        recorder
            .samples
            .lock()
            .iter()
            .filter(|(k, _)| k == key)
            .map(|(_, b)| msg::decode_header(b, MessageKind::from_u8(b[1]).unwrap()).unwrap().0.stamp_sim_ns)
            .collect()
    };
    // Each topic at its rate, judged on simulation time: every stamp on the topic's grid (a
    // multiple of its period), in order, none twice, and never more than the rate allows
    // between 1 s and 3 s. These topics are published with congestion control "drop" (fresh
    // or nothing), so a loaded machine may lose some: a loss count is the bench's to report.
    let in_window = |key: &str| stamps(key).into_iter().filter(|t| (1_000_000_000..3_000_000_000).contains(t)).count();
    for (key, period_ns) in [
        ("vehicle/speed", 10_000_000),
        ("vehicle/state", 10_000_000),
        ("sim/clock", 10_000_000),
        ("camera/front", 50_000_000),
        ("camera/narrow", 50_000_000),
        ("objects", 50_000_000),
    ] {
        let got = stamps(key);
        assert!(!got.is_empty(), "{key}: nothing received");
        assert!(got.iter().all(|t| t % period_ns == 0), "{key}: a stamp off the {period_ns} ns grid");
        assert!(got.windows(2).all(|w| w[0] < w[1]), "{key}: stamps repeat or go back");
        assert!(in_window(key) as u64 <= 2_000_000_000 / period_ns, "{key}: more messages than its rate");
    }
    // Ground truth carries exactly the stamps of the frames it belongs to.
    let frames: Vec<u64> = stamps("camera/front");
    let objects: Vec<u64> = stamps("objects");
    assert!(frames.iter().filter(|t| **t >= 1_000_000_000).all(|t| objects.contains(t)));
    // The narrow camera renders on the front camera's steps, with their stamps.
    let narrow: Vec<u64> = stamps("camera/narrow");
    assert!(narrow.iter().filter(|t| **t >= 1_000_000_000).all(|t| objects.contains(t)));
    // sim/clock reports the measured real-time factor: about 1 in realtime mode.
    let last_clock = recorder
        .samples
        .lock()
        .iter()
        .filter(|(k, _)| k == "sim/clock")
        .map(|(_, b)| msg::decode::<SimClock>(b).unwrap().msg)
        .next_back()
        .unwrap();
    assert!(last_clock.real_time_factor > 0.0, "{last_clock:?}");
    // Realtime: paced to the wall clock, 4 simulated seconds never take less than ~4 s (a
    // loaded machine may take longer; how close to 1 the factor stays is the bench's figure).
    assert!(wall_s >= 3.5, "a realtime run of 4 s took {wall_s:.1} s");

    let frame = recorder.samples.lock().iter().find(|(k, _)| k == "camera/front").map(|(_, b)| b.clone()).unwrap();
    let frame = msg::decode::<msg::CameraFrameRef>(&frame).unwrap().msg;
    assert_eq!(
        (frame.width, frame.height, frame.encoding, frame.data.len()),
        (640, 480, msg::ImageEncoding::Rgb8, 640 * 480 * 3)
    );
    let narrow = recorder.samples.lock().iter().find(|(k, _)| k == "camera/narrow").map(|(_, b)| b.clone()).unwrap();
    let narrow = msg::decode::<msg::CameraFrameRef>(&narrow).unwrap().msg;
    // As configured (config/sim.json5's narrow_camera), raw RGB8.
    let want = SimSettings::default()
        .narrow_camera_info(msg::ImageEncoding::Rgb8)
        .expect("the narrow camera is on by default");
    assert_eq!(
        (narrow.width, narrow.height, narrow.data.len()),
        (want.width, want.height, (want.width * want.height * 3) as usize)
    );
    let events = recorder.events();
    assert!(matches!(&events.last().unwrap().kind, SimEventKind::ScenarioEnd { success: true, .. }), "{events:?}");
}

#[test]
fn bad_scenarios_and_settings_are_clear_errors() {
    let dir = std::env::temp_dir().join(format!("slipstream-sim-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let bad = dir.join("bad.json5");
    std::fs::write(&bad, "{ name: 'bad', duration_s: 10, ego: { lane: 3, speed_mps: 20 } }").unwrap();
    let out = sim_bin().args(["--scenario", bad.to_str().unwrap()]).output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        err.contains("bad.json5")
            && err.contains("key `ego.lane`")
            && err.contains("lanes are numbered 0 (rightmost) to 2"),
        "{err}"
    );

    let out = sim_bin().args(["--scenario", "nope"]).output().unwrap();
    assert!(!out.status.success() && String::from_utf8_lossy(&out.stderr).contains("cut-in"));

    let out = sim_bin().args(["--camera-size", "640by480"]).output().unwrap();
    assert!(String::from_utf8_lossy(&out.stderr).contains("write e.g. 640x480"));

    let out = sim_bin().arg("--list-scenarios").output().unwrap();
    let list = String::from_utf8_lossy(&out.stdout);
    for name in [
        "steady-follow",
        "approach-slower-lead",
        "lead-brakes-to-stop",
        "stop-and-go",
        "cut-in",
        "cut-out-revealing-stopped-car",
        "busy-traffic",
    ] {
        assert!(list.contains(name), "{list}");
    }

    let png = dir.join("frame.png");
    let out =
        sim_bin().args(["--scenario", "cut-in", "--preview", png.to_str().unwrap(), "--at", "2"]).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let img = image::load_from_memory(&std::fs::read(&png).unwrap()).unwrap();
    assert_eq!((img.width(), img.height()), (640, 480));
    let _ = std::fs::remove_dir_all(&dir);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn lockstep_explains_answers_from_a_controller_that_does_not_name_itself() {
    let (session, ep) = listening_session().await;
    let map = TopicMap::default();
    // Alive as "ctl", but its answers carry no attachment (a hand-written client's mistake).
    let bus = Bus::from_session(session.clone(), map.clone(), "ctl").await.unwrap();
    let states = bus.subscriber(topics::VEHICLE_STATE).await.unwrap();
    let control_key = map.key(topics::VEHICLE_CONTROL.topic);
    let answer = tokio::spawn(async move {
        loop {
            let r = states.recv().await;
            let cmd = ControlCommand { answers_step: Some(r.msg.step), ..ControlCommand::NEUTRAL };
            session.put(&control_key, msg::encode(&r.header, &cmd)).await.unwrap();
        }
    });
    let dir = std::env::temp_dir().join(format!("slipstream-sim-unnamed-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let settings_file = dir.join("sim.json5");
    std::fs::write(&settings_file, "{ lockstep: { step_timeout_ms: 300, on_timeout: 'stop' } }").unwrap();
    let mut cmd = sim_bin();
    cmd.args([
        "--mode",
        "lockstep",
        "--wait-for",
        "ctl",
        "--camera-size",
        "160x120",
        "--json",
        "-e",
        &ep,
        "-l",
        "tcp/127.0.0.1:0",
    ])
    .arg("--settings")
    .arg(&settings_file);
    let out = within!(tokio::task::spawn_blocking(move || cmd.output())).unwrap().unwrap();
    answer.abort();
    let _ = std::fs::remove_dir_all(&dir);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    assert!(
        stderr.contains(
            "waiting for ctl (step 0 was answered by (unnamed), which lockstep.wait_for does not list: a controller attaches its node name)"
        ),
        "{stderr}"
    );
    let report: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!((report["steps"].as_u64(), report["lockstep_timeouts"].as_u64()), (Some(0), Some(1)), "{report}");
    drop(bus);
}

/// Busy threads that load the machine until dropped (or for at most `limit`).
struct Load {
    stop: Arc<std::sync::atomic::AtomicBool>,
    threads: Vec<std::thread::JoinHandle<u64>>,
}

impl Load {
    fn start(threads: usize, limit: Duration) -> Load {
        let stop = Arc::new(std::sync::atomic::AtomicBool::new(false));
        let threads = (0..threads)
            .map(|_| {
                let stop = stop.clone();
                std::thread::spawn(move || {
                    let deadline = Instant::now() + limit;
                    let (mut a, mut b) = (vec![1u8; 1 << 20], vec![0u8; 1 << 20]);
                    let mut rounds = 0u64;
                    while !stop.load(std::sync::atomic::Ordering::Relaxed) && Instant::now() < deadline {
                        b.copy_from_slice(&a);
                        let i = rounds as usize % a.len();
                        a[i] ^= b[0];
                        rounds += 1;
                    }
                    rounds
                })
            })
            .collect();
        Load { stop, threads }
    }
}

impl Drop for Load {
    fn drop(&mut self) {
        self.stop.store(true, std::sync::atomic::Ordering::Relaxed);
        for t in self.threads.drain(..) {
            let _ = t.join();
        }
    }
}

/// Every thread's stack of this process, by gdb, into `path` (a stall's evidence). gdb writes
/// the file itself: it stops every thread here while it works, this one too, so a pipe read
/// here would fill and hold gdb forever.
fn dump_stacks(path: &std::path::Path) {
    let _ = std::fs::create_dir_all(path.parent().unwrap());
    let Ok(file) = std::fs::File::create(path) else { return };
    let Ok(err) = file.try_clone() else { return };
    let pid = std::process::id().to_string();
    let _ = Command::new("gdb")
        .args(["-p", &pid, "-batch", "-ex", "thread apply all bt"])
        .stdin(Stdio::null())
        .stdout(file)
        .stderr(err)
        .status();
}

/// This process's resident memory now, MiB.
fn rss_mib() -> f64 {
    let status = std::fs::read_to_string("/proc/self/status").unwrap_or_default();
    let kib = status.lines().find(|l| l.starts_with("VmRSS:")).and_then(|l| l.split_whitespace().nth(1));
    kib.and_then(|k| k.parse::<f64>().ok()).unwrap_or(0.0) / 1024.0
}

/// Issue 41's io_uring question as a test: the lockstep determinism run, repeated under load
/// (two busy threads on this 2-core machine) until a run stalls or SLIPSTREAM_STRESS_RUNS (50)
/// pass, every run's stream identical to the first. A run still going after 15 s (a clean one
/// takes ~1-3 s) has every thread's stack written by gdb to
/// target/test-reports/lockstep-stall-<run>.txt before the run's own 20 s time-out fails it.
/// Ignored in the test command (minutes of load); scripts/stress-lockstep.sh runs it on the
/// default build and on one with `--features uring`.
#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
#[ignore]
async fn lockstep_stress_under_load() {
    let runs: u64 = std::env::var("SLIPSTREAM_STRESS_RUNS").ok().and_then(|v| v.parse().ok()).unwrap_or(50);
    let reports = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("target/test-reports");
    let current = Arc::new(Mutex::new(None::<(u64, Instant)>));
    let watched = current.clone();
    let done = Arc::new(std::sync::atomic::AtomicBool::new(false));
    let finished = done.clone();
    let watchdog = std::thread::spawn(move || {
        let mut dumped = None;
        while !finished.load(std::sync::atomic::Ordering::Relaxed) {
            std::thread::sleep(Duration::from_millis(200));
            let Some((run, since)) = *watched.lock() else { continue };
            if since.elapsed() > Duration::from_secs(15) && dumped != Some(run) {
                dump_stacks(&reports.join(format!("lockstep-stall-{run}.txt")));
                dumped = Some(run);
            }
        }
    });
    let _load = Load::start(2, Duration::from_secs(30 * 60));
    let mut first = None;
    let mut walls = Vec::new();
    for run in 0..runs {
        let started = Instant::now();
        *current.lock() = Some((run, started));
        let stream = lockstep_run("cut-in", 5).await;
        walls.push(started.elapsed().as_secs_f64());
        eprintln!("run {run}: {:.2} s, resident {:.0} MiB", started.elapsed().as_secs_f64(), rss_mib());
        match &first {
            None => first = Some(stream),
            Some(f) => assert!(f == &stream, "run {run}: the stream differs from run 0's"),
        }
    }
    *current.lock() = None;
    done.store(true, std::sync::atomic::Ordering::Relaxed);
    let _ = watchdog.join();
    walls.sort_by(f64::total_cmp);
    eprintln!(
        "lockstep stress: {runs} runs under load, no stall; wall per run: median {:.2} s, max {:.2} s",
        walls[walls.len() / 2],
        walls[walls.len() - 1]
    );
}
