//! The simulator's control input, per controlled vehicle: commands handed from Zenoh's thread
//! to the loop ([`ControlInbox`]), what the vehicle does when they stop ([`Policy`]), and the
//! lockstep answers to one step ([`await_answers`]). Kept apart from publishing: the rules
//! for when a command counts are the part of the simulator a controller's author reads.

use std::collections::{BTreeMap, BTreeSet, VecDeque};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use parking_lot::Mutex;

use super::settings::{BeforeFirst, ControlPolicy};
use super::world::EgoInput;
use slipstream_contract::bus::{Arrivals, Received};
use slipstream_contract::msg::{ControlCommand, ControlTiming};

/// Commands as they arrive, handed from Zenoh's thread to the loop.
#[derive(Default)]
pub(crate) struct ControlInbox {
    queue: Mutex<VecDeque<Received<ControlCommand>>>,
    pub(crate) notify: tokio::sync::Notify,
}

impl ControlInbox {
    const CAPACITY: usize = 1024;

    pub(crate) fn push(&self, r: Received<ControlCommand>) {
        let mut q = self.queue.lock();
        if q.len() >= Self::CAPACITY {
            q.pop_front();
        }
        q.push_back(r);
        drop(q);
        self.notify.notify_one();
    }

    pub(crate) fn drain(&self) -> Vec<Received<ControlCommand>> {
        self.queue.lock().drain(..).collect()
    }
}

/// What the ego does when commands stop.
pub(crate) struct Policy {
    spec: ControlPolicy,
    /// The newest command, the simulated time it came at, and its timing (applied_ns 0 until
    /// first applied).
    last: Option<(ControlCommand, u64, ControlTiming)>,
    braking: bool,
    pub(crate) timeouts: u64,
    pub(crate) stale: u64,
}

impl Policy {
    pub(crate) fn new(spec: ControlPolicy) -> Policy {
        Policy { spec, last: None, braking: false, timeouts: 0, stale: 0 }
    }

    pub(crate) fn on_command(&mut self, cmd: &Received<ControlCommand>, now_ns: u64) {
        let stamp = cmd.header.stamp_sim_ns;
        let age_ns = now_ns.saturating_sub(stamp);
        if self.spec.max_age_ms > 0 && stamp != 0 && age_ns > self.spec.max_age_ms * 1_000_000 {
            self.stale += 1;
            if self.stale.is_power_of_two() {
                tracing::warn!(
                    age_ms = age_ns / 1_000_000,
                    max_age_ms = self.spec.max_age_ms,
                    stale = self.stale,
                    from = cmd.source.as_deref().unwrap_or("?"),
                    "vehicle/control answers a state {} ms old: not applied",
                    age_ns / 1_000_000
                );
            }
            return;
        }
        if self.braking {
            tracing::info!("vehicle/control resumed");
            self.braking = false;
        }
        let timing = ControlTiming { command_stamp_pub_ns: cmd.header.stamp_pub_ns, applied_ns: 0 };
        self.last = Some((cmd.msg, now_ns, timing));
    }

    /// The timing of the command in effect, for vehicle/state; None when none is.
    pub(crate) fn timing(&self) -> Option<ControlTiming> {
        match self.last {
            Some((_, _, t)) if !self.braking && t.applied_ns != 0 => Some(t),
            _ => None,
        }
    }

    pub(crate) fn input(&mut self, now_ns: u64) -> EgoInput {
        let brake = ControlCommand { brake: self.spec.timeout_brake, ..ControlCommand::NEUTRAL };
        match self.last {
            None => match self.spec.before_first {
                BeforeFirst::Cruise => EgoInput::Cruise,
                BeforeFirst::Brake => EgoInput::Command(brake),
            },
            Some((cmd, at, ref mut timing)) if now_ns.saturating_sub(at) <= self.spec.hold_ms * 1_000_000 => {
                if timing.applied_ns == 0 {
                    timing.applied_ns = slipstream_contract::msg::wall_clock_ns();
                }
                EgoInput::Command(cmd)
            }
            Some(_) => {
                if !self.braking {
                    tracing::warn!(
                        hold_ms = self.spec.hold_ms,
                        brake = self.spec.timeout_brake,
                        "no vehicle/control for {} ms of simulated time: braking until a command arrives",
                        self.spec.hold_ms
                    );
                    self.braking = true;
                    self.timeouts += 1;
                }
                EgoInput::Command(brake)
            }
        }
    }
}

/// The answers to one lockstep step.
pub(crate) struct Answers {
    /// The command of the first awaited node that answered.
    pub(crate) command: Option<Received<ControlCommand>>,
    /// With injected faults: answers to earlier steps that faults held back until now (applied
    /// before `command`, in their order).
    pub(crate) earlier: Vec<Received<ControlCommand>>,
    /// Awaited nodes that did not answer in time.
    pub(crate) late: Vec<String>,
    /// Senders of answers to this step that lockstep does not wait for ("(unnamed)": no
    /// attachment): usually a controller started under another name.
    pub(crate) strangers: BTreeSet<String>,
    /// Awaited nodes whose commands answered another step than this one, with the step the
    /// last of them named (None: a command naming no step): why a node is late when it did
    /// send something.
    pub(crate) off_step: BTreeMap<String, Option<u64>>,
}

impl Answers {
    /// Why awaited node `name` did not answer, as far as the step saw: the step its commands
    /// named instead, or who answered in its place. None when nothing came.
    pub(crate) fn why_late(&self, name: &str, k: u64) -> Option<String> {
        match self.off_step.get(name) {
            Some(Some(step)) => Some(format!("its commands answered step {step}, not {k}")),
            Some(None) => Some("its commands name no step (answers_step is missing)".to_string()),
            None if !self.strangers.is_empty() => Some(format!(
                "step {k} was answered by {}, which lockstep.wait_for does not list: a controller attaches its node name",
                self.strangers.iter().cloned().collect::<Vec<_>>().join(", ")
            )),
            None => None,
        }
    }
}

/// Collects the answers to step `k` (stamped `t_ns`) until every awaited node answered or the
/// timeout passed. With injected faults (`faulted`) an answer counts once it arrived, even if
/// the faults dropped or held it: the step goes on with what was delivered.
#[allow(clippy::too_many_arguments)]
pub(crate) async fn await_answers(
    inbox: &ControlInbox,
    arrivals: &Arrivals,
    faulted: bool,
    wait_for: &[String],
    k: u64,
    t_ns: u64,
    timeout_ms: u64,
    stop: &AtomicBool,
) -> Answers {
    let deadline = tokio::time::Instant::now() + Duration::from_millis(timeout_ms);
    let mut answers: BTreeMap<&str, Received<ControlCommand>> = BTreeMap::new();
    let mut earlier = Vec::new();
    let mut strangers = BTreeSet::new();
    let mut off_step = BTreeMap::new();
    let arrived = |n: &String| faulted && arrivals.since_from(n, t_ns);
    loop {
        // Arrivals first: an answer seen arrived was handed on before, so the drain gets it.
        let all_arrived = wait_for.iter().all(arrived);
        for r in inbox.drain() {
            let from = r.source.as_deref().and_then(|s| wait_for.iter().find(|n| n.as_str() == s));
            match (from, r.msg.answers_step) {
                (Some(name), Some(step)) if step == k => {
                    answers.insert(name.as_str(), r);
                }
                (Some(_), Some(step)) if faulted && step < k => earlier.push(r),
                (None, Some(step)) if step == k => {
                    strangers.insert(r.source.clone().unwrap_or_else(|| "(unnamed)".into()));
                }
                (Some(name), step) if !faulted || step.is_none_or(|s| s > k) => {
                    tracing::debug!(source = %name, ?step, waiting_for = k, "vehicle/control answers another step");
                    off_step.insert(name.clone(), step);
                }
                (_, step) => {
                    tracing::debug!(source = ?r.source, ?step, waiting_for = k, "vehicle/control ignored in lockstep")
                }
            }
        }
        let now = tokio::time::Instant::now();
        let answered = |n: &String| answers.contains_key(n.as_str()) || arrived(n);
        if all_arrived || wait_for.iter().all(answered) || stop.load(Ordering::SeqCst) || now >= deadline {
            break;
        }
        // Wake at least every 100 ms to notice a stop request.
        let wake = deadline.min(now + Duration::from_millis(100)) - now;
        tokio::select! {
            _ = tokio::time::timeout(wake, inbox.notify.notified()) => {}
            _ = arrivals.wait(wake, || wait_for.iter().all(arrived)) => {}
        }
    }
    let answered = |n: &&String| answers.contains_key(n.as_str()) || arrived(n);
    let late = wait_for.iter().filter(|n| !answered(n)).cloned().collect();
    Answers { command: wait_for.iter().find_map(|n| answers.remove(n.as_str())), earlier, late, strangers, off_step }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn policy(before_first: BeforeFirst) -> Policy {
        Policy::new(ControlPolicy { hold_ms: 200, timeout_brake: 0.4, max_age_ms: 1000, before_first })
    }

    #[test]
    fn the_last_command_holds_then_the_ego_brakes_until_control_resumes() {
        let mut p = policy(BeforeFirst::Cruise);
        assert_eq!(p.input(0), EgoInput::Cruise);
        let go = ControlCommand { throttle: 0.7, ..ControlCommand::NEUTRAL };
        let sent = |stamp_pub_ns| Received {
            header: slipstream_contract::msg::Header { seq: 0, stamp_sim_ns: 0, stamp_pub_ns },
            msg: go,
            source: None,
        };
        p.on_command(&sent(42), 1_000_000_000);
        assert_eq!(p.timing(), None, "not applied yet");
        assert_eq!(p.input(1_000_000_000), EgoInput::Command(go));
        let timing = p.timing().expect("applied");
        assert_eq!(timing.command_stamp_pub_ns, 42);
        assert!(timing.applied_ns > 0);
        assert_eq!(p.input(1_200_000_000), EgoInput::Command(go), "held for 200 ms");
        assert_eq!(p.timing(), Some(timing), "the first application is kept");
        let brake = EgoInput::Command(ControlCommand { brake: 0.4, ..ControlCommand::NEUTRAL });
        assert_eq!(p.input(1_210_000_000), brake);
        assert_eq!(p.input(5_000_000_000), brake);
        assert_eq!(p.timeouts, 1, "one timeout, however long it lasts");
        assert_eq!(p.timing(), None, "no command in effect while braking");
        p.on_command(&sent(43), 6_000_000_000);
        assert_eq!(p.input(6_010_000_000), EgoInput::Command(go));
        assert_eq!(policy(BeforeFirst::Brake).input(0), brake);
    }

    #[test]
    fn a_command_answering_an_old_state_is_counted_not_applied() {
        let mut p = policy(BeforeFirst::Cruise);
        let cmd = |throttle, stamp_sim_ns| Received {
            header: slipstream_contract::msg::Header { seq: 0, stamp_sim_ns, stamp_pub_ns: 1 },
            msg: ControlCommand { throttle, ..ControlCommand::NEUTRAL },
            source: Some("acc".into()),
        };
        p.on_command(&cmd(0.5, 9_000_000_000), 10_000_000_000);
        assert_eq!(p.input(10_000_000_000), EgoInput::Command(cmd(0.5, 0).msg), "1 s old: still applied");
        // Queued while a link was down, delivered 4 s late: the ego keeps its newer command.
        p.on_command(&cmd(0.9, 6_000_000_000), 10_010_000_000);
        assert_eq!(p.input(10_010_000_000), EgoInput::Command(cmd(0.5, 0).msg));
        assert_eq!(p.stale, 1);
        // Unstamped commands (stamp 0, e.g. a joystick) are taken as fresh.
        p.on_command(&cmd(0.2, 0), 10_020_000_000);
        assert_eq!(p.input(10_020_000_000), EgoInput::Command(cmd(0.2, 0).msg));
        assert_eq!(p.stale, 1);
    }
}
