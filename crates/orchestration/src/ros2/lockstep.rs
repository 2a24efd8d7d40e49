//! A ROS 2 controller in a lockstep loop: ROS has no step numbers, so a command answers the
//! state whose time its header carries. The controller answers each odometry message with one
//! AckermannDriveStamped stamped with the odometry's `header.stamp` (the simulated time of
//! that vehicle/state, exactly: both are built from the same nanoseconds), and the bridge
//! sends it on as vehicle/control naming that state's step and copying its stamp, which is what
//! the simulator's lockstep waits for (docs/node-contract.md). A command stamped with no
//! awaited state's time answers nothing and is refused, counted like any other refusal.

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

/// The states not answered yet, oldest first.
#[derive(Debug, Default)]
pub(crate) struct StepAnswers {
    awaited: VecDeque<Awaited>,
}

impl StepAnswers {
    /// A state arrived: it now awaits its command.
    pub(crate) fn state(&mut self, state: Awaited) {
        if self.awaited.len() == KEPT {
            self.awaited.pop_front();
        }
        self.awaited.push_back(state);
    }

    /// The state a command stamped `stamp` answers; it and every older one are answered then
    /// (the simulator moved past them).
    pub(crate) fn answer(&mut self, stamp: Time) -> Result<Awaited, NoState> {
        let stamp_ns = u64::try_from(stamp.sec).unwrap_or(0) * 1_000_000_000 + u64::from(stamp.nanosec);
        let at = self.awaited.iter().position(|a| a.stamp_sim_ns == stamp_ns).ok_or(NoState { stamp_ns })?;
        let found = self.awaited[at];
        self.awaited.drain(..=at);
        Ok(found)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn state(step: u64) -> Awaited {
        Awaited { step, stamp_sim_ns: step * 10_000_000, speed_mps: 20.0 }
    }

    #[test]
    fn a_command_answers_the_state_of_its_stamp_once() {
        let mut answers = StepAnswers::default();
        answers.state(state(1));
        answers.state(state(2));
        let found = answers.answer(Time::from_ns(20_000_000)).unwrap();
        assert_eq!(found.step, 2);
        // Step 1 was passed over, step 2 answered: neither is answered again.
        assert!(answers.answer(Time::from_ns(10_000_000)).is_err());
        assert!(answers.answer(Time::from_ns(20_000_000)).is_err());
    }

    #[test]
    fn a_command_stamped_with_no_state_s_time_answers_nothing() {
        let mut answers = StepAnswers::default();
        answers.state(state(3));
        let refused = answers.answer(Time::from_ns(31_000_000)).unwrap_err();
        assert_eq!(refused.stamp_ns, 31_000_000);
        assert!(refused.to_string().contains("copy the odometry's header.stamp"));
        assert_eq!(answers.answer(Time::from_ns(30_000_000)).unwrap().step, 3);
    }

    #[test]
    fn a_silent_controller_leaves_a_bounded_queue() {
        let mut answers = StepAnswers::default();
        for step in 0..1000 {
            answers.state(state(step));
        }
        assert_eq!(answers.awaited.len(), KEPT);
        assert!(answers.answer(Time::from_ns(0)).is_err(), "the oldest states were let go");
        assert_eq!(answers.answer(Time::from_ns(999 * 10_000_000)).unwrap().step, 999);
    }
}
