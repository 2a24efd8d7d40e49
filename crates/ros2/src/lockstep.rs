//! A ROS 2 controller in a lockstep loop: ROS has no step numbers, so a command answers the
//! state whose time its header carries. The controller answers each odometry message with one
//! AckermannDriveStamped stamped with the odometry's `header.stamp` (the simulated time of
//! that vehicle/state, exactly: both are built from the same nanoseconds), and the bridge
//! sends it on as vehicle/control naming that state's step and copying its stamp, which is what
//! the simulator's lockstep waits for (docs/node-contract.md). A command stamped with no
//! awaited state's time answers nothing and is refused, counted like any other refusal. The
//! odometry and the state it answers reach the bridge by different links, in no set order, so
//! a command may come before its state: it is held until the state comes.

use std::collections::VecDeque;

use super::messages::Time;

/// States kept awaiting an answer: a lockstep simulator has one at a time; more are kept so
/// that a late answer still finds its state, bounded so that a silent controller costs nothing.
const KEPT: usize = 64;

/// A vehicle/state waiting for the command that answers it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Awaited {
    pub step: u64,
    pub stamp_sim_ns: u64,
    pub speed_mps: f64,
}

/// Why a stamped command answers no step.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct NoState {
    pub stamp_ns: u64,
}

impl std::fmt::Display for NoState {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "stamped {} ns, the time of no state awaiting an answer (copy the odometry's header.stamp)",
            self.stamp_ns
        )
    }
}

/// How far past the newest state a command's stamp may be and still be held for its state:
/// the state and the odometry made from it reach the bridge by different links, so the answer
/// can arrive first. One second of simulated time is far more than that and far less than a
/// stamp from another clock.
const EARLY_NS: u64 = 1_000_000_000;

/// What a command comes to.
#[derive(Debug, PartialEq)]
pub(crate) enum Answer<C> {
    /// It answers this state: send it on.
    Now(Awaited, C),
    /// Its state has not arrived yet: kept until it does (or a newer one does).
    Held,
    /// It answers no state.
    Refused(NoState),
}

/// The states not answered yet, oldest first, and the commands that came before their state.
#[derive(Debug)]
pub(crate) struct StepAnswers<C> {
    awaited: VecDeque<Awaited>,
    early: VecDeque<(u64, C)>,
    newest_ns: Option<u64>,
}

impl<C> Default for StepAnswers<C> {
    fn default() -> Self {
        StepAnswers { awaited: VecDeque::new(), early: VecDeque::new(), newest_ns: None }
    }
}

impl<C> StepAnswers<C> {
    /// A state arrived: a command held for it answers it now, held ones older than it answer
    /// nothing; otherwise it awaits its command.
    pub(crate) fn state(&mut self, state: Awaited) -> Vec<Answer<C>> {
        self.newest_ns = Some(state.stamp_sim_ns);
        let mut out = Vec::new();
        let mut answered = false;
        while self.early.front().is_some_and(|(t, _)| *t <= state.stamp_sim_ns) {
            let Some((stamp_ns, cmd)) = self.early.pop_front() else { break };
            match stamp_ns == state.stamp_sim_ns && !answered {
                true => {
                    answered = true;
                    out.push(Answer::Now(state, cmd));
                }
                false => out.push(Answer::Refused(NoState { stamp_ns })),
            }
        }
        if answered {
            self.awaited.clear();
        } else {
            if self.awaited.len() == KEPT {
                self.awaited.pop_front();
            }
            self.awaited.push_back(state);
        }
        out
    }

    /// What a command stamped `stamp` comes to; a state it answers and every older one are
    /// answered then (the simulator moved past them).
    pub(crate) fn answer(&mut self, stamp: Time, cmd: C) -> Answer<C> {
        let stamp_ns = u64::try_from(stamp.sec).unwrap_or(0) * 1_000_000_000 + u64::from(stamp.nanosec);
        if let Some(at) = self.awaited.iter().position(|a| a.stamp_sim_ns == stamp_ns) {
            let found = self.awaited[at];
            self.awaited.drain(..=at);
            return Answer::Now(found, cmd);
        }
        let ahead = self.newest_ns.is_none_or(|n| stamp_ns > n && stamp_ns - n <= EARLY_NS);
        if ahead && self.early.len() < KEPT && self.early.back().is_none_or(|(t, _)| *t < stamp_ns) {
            self.early.push_back((stamp_ns, cmd));
            return Answer::Held;
        }
        Answer::Refused(NoState { stamp_ns })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn state(step: u64) -> Awaited {
        Awaited { step, stamp_sim_ns: step * 10_000_000, speed_mps: 20.0 }
    }

    fn answered<C>(a: Answer<C>) -> u64 {
        match a {
            Answer::Now(state, _) => state.step,
            _ => panic!("not answered"),
        }
    }

    #[test]
    fn a_command_answers_the_state_of_its_stamp_once() {
        let mut answers = StepAnswers::default();
        answers.state(state(1));
        answers.state(state(2));
        assert_eq!(answered(answers.answer(Time::from_ns(20_000_000), ())), 2);
        // Step 1 was passed over, step 2 answered: neither is answered again.
        assert!(matches!(answers.answer(Time::from_ns(10_000_000), ()), Answer::Refused(_)));
        assert!(matches!(answers.answer(Time::from_ns(20_000_000), ()), Answer::Refused(_)));
    }

    #[test]
    fn a_command_stamped_with_no_state_s_time_answers_nothing() {
        let mut answers = StepAnswers::default();
        answers.state(state(3));
        let Answer::Refused(refused) = answers.answer(Time::from_ns(29_000_000), ()) else { panic!("not refused") };
        assert_eq!(refused.stamp_ns, 29_000_000);
        assert!(refused.to_string().contains("copy the odometry's header.stamp"));
        // Another clock's time, far past the newest state, is refused at once too.
        assert!(matches!(answers.answer(Time::from_ns(5_000_000_000), ()), Answer::Refused(_)));
        assert_eq!(answered(answers.answer(Time::from_ns(30_000_000), ())), 3);
    }

    #[test]
    fn a_command_arriving_before_its_state_answers_it_when_the_state_comes() {
        let mut answers = StepAnswers::default();
        answers.state(state(1));
        assert_eq!(answers.answer(Time::from_ns(20_000_000), "second"), Answer::Held);
        let out = answers.state(state(2));
        assert_eq!(out, vec![Answer::Now(state(2), "second")]);
        // Answered: the state awaits nothing more.
        assert!(matches!(answers.answer(Time::from_ns(20_000_000), "again"), Answer::Refused(_)));
    }

    #[test]
    fn a_held_command_whose_state_never_comes_is_refused_by_a_newer_state() {
        let mut answers = StepAnswers::default();
        answers.state(state(1));
        assert_eq!(answers.answer(Time::from_ns(15_000_000), ()), Answer::Held);
        let out = answers.state(state(2));
        assert_eq!(out, vec![Answer::Refused(NoState { stamp_ns: 15_000_000 })]);
        assert_eq!(answered(answers.answer(Time::from_ns(20_000_000), ())), 2);
    }

    #[test]
    fn a_silent_controller_leaves_a_bounded_queue() {
        let mut answers = StepAnswers::default();
        for step in 0..1000 {
            answers.state(state(step));
        }
        assert_eq!(answers.awaited.len(), KEPT);
        assert!(matches!(answers.answer(Time::from_ns(0), ()), Answer::Refused(_)), "the oldest states were let go");
        assert_eq!(answered(answers.answer(Time::from_ns(999 * 10_000_000), ())), 999);
    }
}
