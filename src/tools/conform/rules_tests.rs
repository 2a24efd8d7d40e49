use super::*;
use crate::msg::{CameraInfo, Header, ImageEncoding, SimClock};
use crate::tools::conform::observed::{FrameSeen, KeyLog, LockstepLog, ObjectSeen, ProbeLog};
use crate::tools::conform::watch::PROBE;

const HZ: u64 = 500;

fn stamp(step: u64) -> u64 {
    step * 1_000_000_000 / HZ
}

fn log(key: &str, steps: impl Iterator<Item = u64>) -> KeyLog {
    let mut l = KeyLog::new(key);
    for (seq, k) in steps.enumerate() {
        let t = stamp(k);
        l.push(Header { seq: seq as u64, stamp_sim_ns: t, stamp_pub_ns: 0 }, t as f64 / 1e9);
    }
    l
}

/// Two seconds of a simulator that keeps the contract in realtime: speed, state and clock at
/// 100 Hz, frames and ground truth at 20 Hz, the probe applied 30 ms after it went out.
fn good() -> Observed {
    let every = |n: u64| (0..2 * HZ).step_by(n as usize);
    let info = CameraInfo::pinhole(640, 480, 1.0, [1.6, 0.0, 1.35], [0.0, 0.05, 0.0], 20.0, ImageEncoding::Rgb8);
    let mut o = Observed {
        window_s: 2.0,
        speed: log("vehicle/speed", every(5)),
        state: log("vehicle/state", every(5)),
        clock: log("sim/clock", every(5)),
        camera: log("camera/front", every(25)),
        camera_info: log("camera/front/info", std::iter::once(0)),
        objects: log("objects", every(25)),
        road: KeyLog::new("sim/road"),
        ego: KeyLog::new("sim/ego"),
        narrow: KeyLog::new("camera/narrow"),
        events: KeyLog::new("sim/events"),
        info: Some(info),
        late_info_asked: true,
        late_info_after_s: Some(0.01),
        probe: Some(ProbeLog { started_s: 1.5, command: Some(PROBE), sent: 3 }),
        ..Observed::default()
    };
    o.clocks = every(5)
        .map(|k| SimClock { step: k, real_time_factor: 1.0, mode: SimMode::Realtime, physics_hz: HZ as f64 })
        .collect();
    o.frames = every(25).map(|_| FrameSeen { width: 640, height: 480, encoding: ImageEncoding::Rgb8 }).collect();
    // A lead 30 m ahead closing at 2 m/s.
    o.objects_seen = every(25)
        .map(|k| ObjectSeen {
            stamp_sim_ns: stamp(k),
            id: 7,
            position_in_ego_m: [30.0 - 2.0 * stamp(k) as f64 / 1e9, 0.0],
            velocity_in_ego_mps: [-2.0, 0.0],
        })
        .collect();
    o.states = every(5)
        .map(|k| {
            let applied = if stamp(k) as f64 / 1e9 >= 1.53 { PROBE } else { ControlCommand::NEUTRAL };
            StateSeen {
                stamp_sim_ns: stamp(k),
                step: k,
                applied,
                command_stamp_pub_ns: None,
                arrived_s: stamp(k) as f64 / 1e9,
            }
        })
        .collect();
    o
}

fn outcome(o: &Observed, rule: &str) -> (Outcome, String) {
    let v = judge(o).into_iter().find(|v| v.rule == rule).unwrap_or_else(|| panic!("no rule {rule}"));
    (v.outcome, v.detail)
}

fn fails(o: &Observed, rule: &str) -> String {
    let (out, detail) = outcome(o, rule);
    assert_eq!(out, Outcome::Fail, "{rule} should fail: {detail}");
    assert!(failed(&judge(o)));
    detail
}

#[test]
fn a_simulator_that_keeps_the_contract_passes_every_rule_it_can() {
    let verdicts = judge(&good());
    for v in &verdicts {
        assert_ne!(v.outcome, Outcome::Fail, "{v:?}");
    }
    assert!(!failed(&verdicts));
    // Only the optional parts it does not publish are skipped.
    let skipped: Vec<&str> = verdicts.iter().filter(|v| v.outcome == Outcome::Skip).map(|v| v.rule).collect();
    assert_eq!(skipped, ["optional.sim_road", "optional.sim_ego", "optional.camera_narrow"]);
}

#[test]
fn a_missing_required_key_fails_naming_the_key() {
    let mut o = good();
    o.camera = KeyLog::new("ns/camera/front");
    o.frames.clear();
    assert!(fails(&o, "required.camera_front").contains("nothing on ns/camera/front"));
}

#[test]
fn an_undecodable_payload_fails_with_the_decoders_words() {
    let mut o = good();
    o.speed.reject("truncated Speed".into());
    let detail = fails(&o, "required.vehicle_speed");
    assert!(detail.contains("1 of 201") && detail.contains("truncated Speed"), "{detail}");
}

#[test]
fn speed_at_10_hz_fails_the_rate_rule() {
    let mut o = good();
    o.speed = log("vehicle/speed", (0..2 * HZ).step_by(50));
    assert!(fails(&o, "rate.vehicle_speed").contains("10.0 Hz"));
}

#[test]
fn a_camera_off_its_announced_rate_fails() {
    let mut o = good();
    o.info.as_mut().unwrap().rate_hz = 30.0;
    assert!(fails(&o, "rate.camera_front").contains("30.0 Hz"));
}

#[test]
fn simulated_time_off_the_announced_real_time_factor_fails() {
    let mut o = good();
    for c in &mut o.clocks {
        c.real_time_factor = 2.0;
    }
    fails(&o, "rate.real_time_factor");
}

#[test]
fn stamps_going_backwards_fail() {
    let mut o = good();
    o.state.seen[50].header.stamp_sim_ns = 0;
    assert!(fails(&o, "stamps.monotonic").contains("went back"));
}

#[test]
fn a_step_stamped_off_its_time_fails() {
    let mut o = good();
    o.states[10].stamp_sim_ns += 10_000_000;
    assert!(fails(&o, "stamps.steps").contains("vehicle/state step 50"));
}

#[test]
fn frames_between_speed_steps_or_ground_truth_off_the_frame_fail() {
    let mut o = good();
    for s in &mut o.objects.seen {
        s.header.stamp_sim_ns += 1;
    }
    assert!(fails(&o, "stamps.frames_match").contains("objects"));
    let mut o = good();
    for s in &mut o.camera.seen {
        s.header.stamp_sim_ns += 5_000_000;
    }
    assert!(fails(&o, "stamps.frames_match").contains("between speed steps"));
    // A frame next to a lost speed message is not judged.
    let mut o = good();
    o.speed.seen.retain(|s| s.header.seq % 5 != 0);
    assert_eq!(outcome(&o, "stamps.frames_match").0, Outcome::Skip);
}

#[test]
fn ground_truth_that_moves_otherwise_than_its_velocity_says_fails() {
    let mut o = good();
    for (i, s) in o.objects_seen.iter_mut().enumerate() {
        s.position_in_ego_m[0] -= i as f64 * 0.7; // drifts 14 m/s faster than it says
    }
    assert!(fails(&o, "objects.motion").contains("object 7"));
}

#[test]
fn sequence_gaps_are_counted_and_a_lossy_ego_topic_fails() {
    let mut o = good();
    o.camera.seen.remove(3);
    let (out, detail) = outcome(&o, "seq.gaps");
    assert_eq!(out, Outcome::Pass);
    assert!(detail.contains("camera/front 1"), "{detail}");
    o.speed.seen.retain(|s| s.header.seq % 2 == 0);
    assert!(fails(&o, "seq.gaps").contains("vehicle/speed: 50 %"));
}

#[test]
fn camera_info_a_late_subscriber_never_gets_fails() {
    let mut o = good();
    o.late_info_after_s = None;
    assert!(fails(&o, "camera_info.late_subscriber").contains("latch"));
}

#[test]
fn frames_of_another_size_than_the_info_fail() {
    let mut o = good();
    o.frames[2].width = 320;
    fails(&o, "camera.matches_info");
}

#[test]
fn a_command_never_applied_fails_and_a_late_one_too() {
    let mut o = good();
    for s in &mut o.states {
        s.applied = ControlCommand::NEUTRAL;
    }
    assert!(fails(&o, "control.applied").contains("never showed"));
    let mut o = good();
    o.probe.as_mut().unwrap().started_s = 1.0;
    assert!(fails(&o, "control.applied").contains("at most 250 ms"));
}

fn lockstep() -> Observed {
    let mut o = good();
    o.probe = None;
    for c in &mut o.clocks {
        c.mode = SimMode::Lockstep;
    }
    let mut answered = std::collections::BTreeMap::new();
    for s in &mut o.states {
        if let Some((&k, cmd)) = answered.range(..s.step).next_back() {
            let _: &ControlCommand = cmd;
            s.applied = ControlCommand { answers_step: Some(k), ..*cmd };
        }
        let throttle = if s.step % 2 == 0 { 0.125 } else { 0.0 };
        answered.insert(s.step, ControlCommand { throttle, answers_step: Some(s.step), ..ControlCommand::NEUTRAL });
    }
    o.lockstep = Some(LockstepLog { name: "acc".into(), answered });
    o
}

#[test]
fn lockstep_passes_when_every_state_applies_the_answer_before_it() {
    let o = lockstep();
    assert_eq!(outcome(&o, "lockstep.answered").0, Outcome::Pass);
    assert_eq!(outcome(&o, "lockstep.mode").0, Outcome::Pass);
    assert_eq!(outcome(&o, "rate.real_time_factor").0, Outcome::Skip);
}

#[test]
fn a_simulator_that_steps_on_without_the_answer_fails_lockstep() {
    let mut o = lockstep();
    o.states[40].applied = o.states[39].applied;
    assert!(fails(&o, "lockstep.answered").contains("without waiting"));
    let mut o = lockstep();
    o.ended = Some("ego collided with vehicle 1".into());
    assert!(fails(&o, "scenario.running").contains("ego collided"));
    let mut o = lockstep();
    o.timeouts.push(vec!["acc".into()]);
    assert!(fails(&o, "lockstep.answered").contains("control timeout"));
    let mut o = lockstep();
    o.lockstep.as_mut().unwrap().answered.clear();
    assert!(fails(&o, "lockstep.answered").contains("lockstep.wait_for must list 'acc'"));
    let mut o = good();
    o.lockstep = Some(LockstepLog { name: "acc".into(), ..Default::default() });
    assert!(fails(&o, "lockstep.mode").contains("Realtime"));
}
