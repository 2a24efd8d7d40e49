//! The simulator contract's rules (docs/simulator-contract.md), each judged from what was
//! observed: PASS, FAIL with what was seen, or SKIP with why. Pure: no bus, no clock.

use serde::Serialize;

use super::observed::{KeyLog, Observed, StateSeen};
use crate::msg::{ControlCommand, SimMode};

/// Slowest vehicle/speed and vehicle/state a simulator may publish, in simulated Hz: the ACC
/// decides once per speed message, so this is its slowest control rate.
pub const MIN_EGO_HZ: f64 = 50.0;
/// Slowest sim/clock, simulated Hz.
pub const MIN_CLOCK_HZ: f64 = 10.0;
/// How far the camera's measured rate may stray from camera/front/info's rate_hz.
pub const CAMERA_RATE_TOLERANCE: f64 = 0.10;
/// How far simulated time may run from the real-time factor sim/clock announces (realtime).
pub const RTF_TOLERANCE: f64 = 0.20;
/// A command must show in vehicle/state's `applied` this soon after it was sent (wall clock).
pub const CONTROL_BOUND_S: f64 = 0.25;
/// A subscriber that joins late must get the camera info this soon.
pub const LATE_INFO_BOUND_S: f64 = 3.0;
/// How far ground truth's position_in_ego_m may move from what its velocity_in_ego_mps says,
/// m/s (median over consecutive messages).
pub const OBJECT_SPEED_TOLERANCE: f64 = 0.5;
/// Largest share of vehicle/speed or vehicle/state messages missing from the sequence.
pub const MAX_EGO_LOSS: f64 = 0.05;

/// A rule's result.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "UPPERCASE")]
pub enum Outcome {
    Pass,
    Fail,
    Skip,
}

/// One rule judged.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Verdict {
    /// Stable id, as docs/simulator-contract.md lists it.
    pub rule: &'static str,
    pub outcome: Outcome,
    /// The numbers seen, or why it failed or was skipped.
    pub detail: String,
}

fn verdict(rule: &'static str, ok: bool, detail: String) -> Verdict {
    Verdict { rule, outcome: if ok { Outcome::Pass } else { Outcome::Fail }, detail }
}

fn skip(rule: &'static str, why: impl Into<String>) -> Verdict {
    Verdict { rule, outcome: Outcome::Skip, detail: why.into() }
}

/// Every rule, in the order of the contract.
pub fn judge(o: &Observed) -> Vec<Verdict> {
    let mut out = Vec::new();
    for (rule, log) in [
        ("required.vehicle_speed", &o.speed),
        ("required.vehicle_state", &o.state),
        ("required.sim_clock", &o.clock),
        ("required.camera_front", &o.camera),
        ("required.camera_front_info", &o.camera_info),
    ] {
        out.push(required(rule, log, o.window_s));
    }
    for (rule, log, enables) in [
        ("optional.objects", &o.objects, "scoring against ground truth (eval, up's report)"),
        ("optional.sim_road", &o.road, "lane-aware lead selection in bends"),
        ("optional.sim_ego", &o.ego, "a controller of any make set from the scenario (set speed, time gap, vehicle)"),
        ("optional.camera_narrow", &o.narrow, "long-range detection"),
    ] {
        out.push(optional(rule, log, enables));
    }
    out.push(min_rate("rate.vehicle_speed", &o.speed, MIN_EGO_HZ));
    out.push(min_rate("rate.vehicle_state", &o.state, MIN_EGO_HZ));
    out.push(min_rate("rate.sim_clock", &o.clock, MIN_CLOCK_HZ));
    out.push(camera_rate(o));
    out.push(realtime_factor(o));
    out.push(monotonic(o));
    out.push(steps(o));
    out.push(frames_match(o));
    out.push(objects_motion(o));
    out.push(losses(o));
    out.push(late_info(o));
    out.push(frame_size(o));
    out.extend(control(o));
    out.push(still_running(o));
    out
}

/// The simulator ran its scenario through the whole watch: what ended early was not judged.
fn still_running(o: &Observed) -> Verdict {
    const RULE: &str = "scenario.running";
    match &o.ended {
        Some(reason) => verdict(
            RULE,
            false,
            format!("the simulator ended its scenario during the watch ({reason}): run a longer one, or watch less (--duration)"),
        ),
        None => verdict(RULE, true, format!("running for the whole {:.1} s watch", o.window_s)),
    }
}

/// Any rule failed.
pub fn failed(verdicts: &[Verdict]) -> bool {
    verdicts.iter().any(|v| v.outcome == Outcome::Fail)
}

fn decodes(log: &KeyLog) -> Result<(), String> {
    match (&log.first_bad, log.bad) {
        (Some(e), n) => {
            Err(format!("{n} of {} payloads on {} do not decode; first: {e}", n + log.seen.len() as u64, log.key))
        }
        (None, _) => Ok(()),
    }
}

/// "1 message", "2 messages".
fn count(n: usize, what: &str) -> String {
    if n == 1 {
        format!("1 {what}")
    } else {
        format!("{n} {what}s")
    }
}

fn required(rule: &'static str, log: &KeyLog, window_s: f64) -> Verdict {
    if let Err(e) = decodes(log) {
        return verdict(rule, false, e);
    }
    if log.seen.is_empty() {
        return verdict(rule, false, format!("nothing on {} in {window_s:.1} s", log.key));
    }
    verdict(rule, true, format!("{} on {}, all decode", count(log.seen.len(), "message"), log.key))
}

fn optional(rule: &'static str, log: &KeyLog, enables: &str) -> Verdict {
    if let Err(e) = decodes(log) {
        return verdict(rule, false, e);
    }
    if log.seen.is_empty() {
        return skip(rule, format!("not published on {}: no {enables}", log.key));
    }
    verdict(rule, true, format!("{} on {}, all decode", count(log.seen.len(), "message"), log.key))
}

fn min_rate(rule: &'static str, log: &KeyLog, min_hz: f64) -> Verdict {
    match log.median_interval_s() {
        None => skip(rule, format!("fewer than 2 messages on {}", log.key)),
        Some(dt) if dt <= 0.0 => verdict(rule, false, format!("{}: consecutive messages share a stamp", log.key)),
        Some(dt) => {
            let hz = 1.0 / dt;
            verdict(rule, hz >= min_hz * 0.999, format!("{hz:.1} Hz of simulated time (at least {min_hz} Hz)"))
        }
    }
}

fn camera_rate(o: &Observed) -> Verdict {
    const RULE: &str = "rate.camera_front";
    let Some(info) = &o.info else { return skip(RULE, "no camera info to take the announced rate from") };
    let Some(dt) = o.camera.median_interval_s() else { return skip(RULE, "fewer than 2 frames") };
    let hz = 1.0 / dt.max(1e-9);
    let ok = (hz - info.rate_hz).abs() <= info.rate_hz * CAMERA_RATE_TOLERANCE;
    let detail = format!("{hz:.1} Hz of simulated time; camera info announces {:.1} Hz (+-10 %)", info.rate_hz);
    verdict(RULE, ok, detail)
}

fn realtime_factor(o: &Observed) -> Verdict {
    const RULE: &str = "rate.real_time_factor";
    let Some(last) = o.clocks.last() else { return skip(RULE, "no sim/clock") };
    if last.mode != SimMode::Realtime {
        return skip(RULE, format!("the simulator runs {:?}: no real-time factor to keep", last.mode));
    }
    let seen = &o.speed.seen;
    let (Some(a), Some(b)) = (seen.first(), seen.last()) else { return skip(RULE, "no vehicle/speed") };
    let wall_s = b.arrived_s - a.arrived_s;
    if wall_s < 1.0 {
        return skip(RULE, format!("{wall_s:.2} s of speed messages: too short to measure"));
    }
    let measured = (b.header.stamp_sim_ns.saturating_sub(a.header.stamp_sim_ns)) as f64 / 1e9 / wall_s;
    let mut announced: Vec<f64> = o.clocks.iter().map(|c| c.real_time_factor as f64).filter(|r| *r > 0.0).collect();
    announced.sort_by(f64::total_cmp);
    let Some(&rtf) = announced.get(announced.len() / 2) else {
        return verdict(RULE, false, "sim/clock announces no real-time factor (0) in realtime mode".into());
    };
    let ok = (measured - rtf).abs() <= rtf * RTF_TOLERANCE;
    verdict(
        RULE,
        ok,
        format!("simulated time ran at {measured:.2}x the wall clock; sim/clock announces {rtf:.2}x (+-20 %)"),
    )
}

fn monotonic(o: &Observed) -> Verdict {
    const RULE: &str = "stamps.monotonic";
    for log in [&o.speed, &o.state, &o.clock, &o.camera, &o.objects, &o.narrow] {
        for w in log.seen.windows(2) {
            let (a, b) = (w[0].header, w[1].header);
            if b.seq <= a.seq {
                return verdict(RULE, false, format!("{}: seq {} after {}", log.key, b.seq, a.seq));
            }
            if b.stamp_sim_ns < a.stamp_sim_ns {
                let msg = format!(
                    "{}: stamp_sim_ns {} after {} (simulated time went back)",
                    log.key, b.stamp_sim_ns, a.stamp_sim_ns
                );
                return verdict(RULE, false, msg);
            }
        }
    }
    verdict(RULE, true, "seq rises and simulated time never goes back on any key".into())
}

/// Steps and stamps agree: step k is stamped floor(k * 1e9 / physics_hz).
fn steps(o: &Observed) -> Verdict {
    const RULE: &str = "stamps.steps";
    let Some(hz) = o.clocks.last().map(|c| c.physics_hz) else { return skip(RULE, "no sim/clock") };
    if !(hz.is_finite() && hz > 0.0) {
        return verdict(RULE, false, format!("sim/clock announces physics_hz {hz}"));
    }
    let expected = |step: u64| (step as u128 * 1_000_000_000 / hz.round().max(1.0) as u128) as u64;
    let half_step = (0.5e9 / hz) as u64;
    let off = |step: u64, stamp: u64| expected(step).abs_diff(stamp) > half_step;
    let clocks = o.clock.seen.iter().zip(&o.clocks);
    if let Some((s, c)) = clocks.clone().find(|(s, c)| off(c.step, s.header.stamp_sim_ns)) {
        return verdict(
            RULE,
            false,
            format!("sim/clock step {} is stamped {} ns, not {} ns", c.step, s.header.stamp_sim_ns, expected(c.step)),
        );
    }
    if let Some(s) = o.states.iter().find(|s| off(s.step, s.stamp_sim_ns)) {
        let msg = format!(
            "vehicle/state step {} is stamped {} ns, not {} ns ({hz} Hz)",
            s.step,
            s.stamp_sim_ns,
            expected(s.step)
        );
        return verdict(RULE, false, msg);
    }
    verdict(RULE, true, format!("every step k of sim/clock and vehicle/state stamped k / {hz} Hz"))
}

/// A frame belongs to a step that also published the ego's speed (within half a physics step
/// of a speed message's stamp; frames next to a lost speed message are not judged), and
/// ground truth shares the frame's stamp.
fn frames_match(o: &Observed) -> Verdict {
    const RULE: &str = "stamps.frames_match";
    let speeds = &o.speed.seen;
    if speeds.len() < 2 {
        return skip(RULE, "fewer than 2 speed messages");
    }
    let half_step = o.clocks.last().map_or(500_000, |c| (0.5e9 / c.physics_hz.max(1.0)) as u64);
    let (mut judged, mut off) = (0, None);
    for t in o.camera.seen.iter().map(|s| s.header.stamp_sim_ns) {
        let i = speeds.partition_point(|s| s.header.stamp_sim_ns < t);
        let (Some(a), Some(b)) = (i.checked_sub(1).and_then(|i| speeds.get(i)), speeds.get(i)) else { continue };
        if b.header.seq != a.header.seq + 1 {
            continue;
        }
        judged += 1;
        let near = [a, b].iter().any(|s| s.header.stamp_sim_ns.abs_diff(t) <= half_step);
        if !near && off.is_none() {
            off = Some(t);
        }
    }
    if judged == 0 {
        return skip(RULE, "no frame between two consecutive speed messages");
    }
    if let Some(t) = off {
        return verdict(
            RULE,
            false,
            format!("a frame stamped {t} ns falls between speed steps (frames go out on steps that publish speed)"),
        );
    }
    let frames: std::collections::BTreeSet<u64> = o.camera.seen.iter().map(|s| s.header.stamp_sim_ns).collect();
    let (first, last) = (*frames.first().unwrap_or(&0), *frames.last().unwrap_or(&0));
    let objects: Vec<u64> =
        o.objects.seen.iter().map(|s| s.header.stamp_sim_ns).filter(|t| (first..=last).contains(t)).collect();
    let matched = objects.iter().filter(|t| frames.contains(t)).count();
    if !objects.is_empty() && (matched as f64) < 0.9 * objects.len() as f64 {
        return verdict(
            RULE,
            false,
            format!(
                "{matched} of {} objects messages share a frame's stamp (ground truth belongs to a frame)",
                objects.len()
            ),
        );
    }
    verdict(
        RULE,
        true,
        format!("{judged} frames on speed steps; {matched} of {} objects on a frame's stamp", objects.len()),
    )
}

/// Ground truth moves as it says it does: between two objects messages, each object's
/// position in the ego frame changes by its velocity in the ego frame (within
/// [`OBJECT_SPEED_TOLERANCE`], the median over every pair).
fn objects_motion(o: &Observed) -> Verdict {
    const RULE: &str = "objects.motion";
    let mut by_id: std::collections::BTreeMap<u32, Vec<&super::observed::ObjectSeen>> = Default::default();
    for s in &o.objects_seen {
        by_id.entry(s.id).or_default().push(s);
    }
    let mut errors: Vec<(f64, u32)> = Vec::new();
    for (id, seen) in &by_id {
        for w in seen.windows(2) {
            let dt = w[1].stamp_sim_ns.saturating_sub(w[0].stamp_sim_ns) as f64 / 1e9;
            if !(dt > 0.0 && dt <= 0.5) {
                continue;
            }
            let moved = |i: usize| (w[1].position_in_ego_m[i] - w[0].position_in_ego_m[i]) / dt;
            let said = |i: usize| (w[0].velocity_in_ego_mps[i] + w[1].velocity_in_ego_mps[i]) / 2.0;
            errors.push((((moved(0) - said(0)).powi(2) + (moved(1) - said(1)).powi(2)).sqrt(), *id));
        }
    }
    if errors.is_empty() {
        return skip(RULE, "no object seen in two messages");
    }
    errors.sort_by(|a, b| a.0.total_cmp(&b.0));
    let (median, worst) = (errors[errors.len() / 2].0, errors[errors.len() - 1]);
    let detail = format!(
        "position_in_ego_m moves at velocity_in_ego_mps within {median:.2} m/s (median of {} pairs; worst {:.2} m/s, object {}; at most {OBJECT_SPEED_TOLERANCE} m/s)",
        errors.len(),
        worst.0,
        worst.1
    );
    verdict(RULE, median <= OBJECT_SPEED_TOLERANCE, detail)
}

fn losses(o: &Observed) -> Verdict {
    const RULE: &str = "seq.gaps";
    let mut parts = Vec::new();
    let mut worst: Option<(String, f64)> = None;
    for (log, ego) in [(&o.speed, true), (&o.state, true), (&o.clock, false), (&o.camera, false), (&o.objects, false)] {
        if log.seen.is_empty() {
            continue;
        }
        let gaps = log.gaps();
        parts.push(format!("{} {gaps}", log.key));
        let share = gaps as f64 / (gaps + log.seen.len() as u64) as f64;
        if ego && share > MAX_EGO_LOSS && worst.as_ref().is_none_or(|w| share > w.1) {
            worst = Some((log.key.clone(), share));
        }
    }
    if let Some((key, share)) = worst {
        let msg =
            format!("{key}: {:.0} % of the sequence missing (at most 5 %); gaps: {}", share * 100.0, parts.join(", "));
        return verdict(RULE, false, msg);
    }
    verdict(RULE, true, format!("messages missing from each publisher's sequence: {}", parts.join(", ")))
}

fn late_info(o: &Observed) -> Verdict {
    const RULE: &str = "camera_info.late_subscriber";
    if !o.late_info_asked {
        return skip(RULE, "the watch ended before a late subscriber could join");
    }
    match o.late_info_after_s {
        Some(s) if s <= LATE_INFO_BOUND_S => {
            verdict(RULE, true, format!("a subscriber joining late got it after {:.0} ms", s * 1e3))
        }
        Some(s) => verdict(RULE, false, format!("a late subscriber waited {s:.1} s (at most {LATE_INFO_BOUND_S} s)")),
        None => verdict(
            RULE,
            false,
            format!("a subscriber joining late never got {} (latch it: docs/simulator-contract.md)", o.camera_info.key),
        ),
    }
}

fn frame_size(o: &Observed) -> Verdict {
    const RULE: &str = "camera.matches_info";
    let Some(info) = &o.info else { return skip(RULE, "no camera info") };
    match o.frames.iter().find(|f| (f.width, f.height, f.encoding) != (info.width, info.height, info.encoding)) {
        Some(f) => verdict(
            RULE,
            false,
            format!(
                "a frame is {}x{} {:?}, the camera info says {}x{} {:?}",
                f.width, f.height, f.encoding, info.width, info.height, info.encoding
            ),
        ),
        None if o.frames.is_empty() => skip(RULE, "no frame"),
        None => verdict(
            RULE,
            true,
            format!("{} frames of {}x{} {:?}", o.frames.len(), info.width, info.height, info.encoding),
        ),
    }
}

fn same_pedals(a: &ControlCommand, b: &ControlCommand) -> bool {
    (a.throttle, a.brake, a.steer) == (b.throttle, b.brake, b.steer)
}

/// The control rules: the probe's command applied (realtime, fast), or every lockstep step
/// answered and applied.
fn control(o: &Observed) -> Vec<Verdict> {
    let mode = o.clocks.last().map(|c| c.mode);
    match (&o.lockstep, mode) {
        (Some(l), _) => vec![lockstep_mode(mode), lockstep_applied(o, l)],
        (None, Some(SimMode::Lockstep)) => vec![skip(
            "control.applied",
            "the simulator runs lockstep: run conform with --lockstep (as a node its lockstep.wait_for lists)",
        )],
        (None, _) => vec![probe_applied(o)],
    }
}

fn probe_applied(o: &Observed) -> Verdict {
    const RULE: &str = "control.applied";
    let Some(probe) = &o.probe else { return skip(RULE, "no control probe (--no-control)") };
    let Some(cmd) = &probe.command else { return skip(RULE, "no command sent") };
    let after: Vec<&StateSeen> = o.states.iter().filter(|s| s.arrived_s >= probe.started_s).collect();
    match after.iter().find(|s| same_pedals(&s.applied, cmd)) {
        Some(s) => {
            let latency = s.arrived_s - probe.started_s;
            let detail = format!(
                "throttle {} brake {} steer {} shown applied {:.0} ms after the first of {} commands (at most {:.0} ms)",
                cmd.throttle, cmd.brake, cmd.steer, latency * 1e3, probe.sent, CONTROL_BOUND_S * 1e3
            );
            verdict(RULE, latency <= CONTROL_BOUND_S, detail)
        }
        None => {
            let last = after.last().map_or("no vehicle/state after the first command".into(), |s| {
                format!(
                    "the last state shows throttle {} brake {} steer {}",
                    s.applied.throttle, s.applied.brake, s.applied.steer
                )
            });
            let detail = format!(
                "{} commands (brake {}) on vehicle/control never showed in vehicle/state.applied; {last} (another controller running? one at a time)",
                probe.sent, cmd.brake
            );
            verdict(RULE, false, detail)
        }
    }
}

fn lockstep_mode(mode: Option<SimMode>) -> Verdict {
    const RULE: &str = "lockstep.mode";
    match mode {
        Some(SimMode::Lockstep) => verdict(RULE, true, "sim/clock says Lockstep".into()),
        Some(m) => verdict(RULE, false, format!("sim/clock says {m:?}; --lockstep needs a simulator in lockstep")),
        None => verdict(RULE, false, "no sim/clock".into()),
    }
}

/// Each state after conform's first answer shows the answer to the step before it applied:
/// the simulator waited for it.
fn lockstep_applied(o: &Observed, l: &super::observed::LockstepLog) -> Verdict {
    const RULE: &str = "lockstep.answered";
    let Some(&first) = l.answered.keys().next() else {
        let detail = format!(
            "no step to answer: is the simulator waiting for another node? Its lockstep.wait_for must list '{}'",
            l.name
        );
        return verdict(RULE, false, detail);
    };
    let mut checked = 0;
    for s in o.states.iter().filter(|s| s.step > first) {
        let Some((&step, cmd)) = l.answered.range(..s.step).next_back() else { continue };
        checked += 1;
        if s.applied.answers_step != Some(step) || !same_pedals(&s.applied, cmd) {
            let detail = format!(
                "vehicle/state step {} applied {:?} (answers_step {:?}); conform answered step {step} with throttle {} brake {}: the simulator went on without waiting for the answer",
                s.step, (s.applied.throttle, s.applied.brake), s.applied.answers_step, cmd.throttle, cmd.brake
            );
            return verdict(RULE, false, detail);
        }
    }
    if let Some(late) = o.timeouts.iter().find(|late| late.contains(&l.name)) {
        return verdict(RULE, false, format!("sim/events reported a control timeout for {}", late.join(", ")));
    }
    if checked == 0 {
        return verdict(RULE, false, format!("{} steps answered, but no vehicle/state after them", l.answered.len()));
    }
    verdict(
        RULE,
        true,
        format!(
            "{} steps answered as '{}'; {checked} states each applied the answer to the step before",
            l.answered.len(),
            l.name
        ),
    )
}

#[cfg(test)]
#[path = "rules_tests.rs"]
mod tests;
