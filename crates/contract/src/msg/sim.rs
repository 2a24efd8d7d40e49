//! Simulator clock and events.

use serde::{Deserialize, Serialize};

use super::{Message, MessageKind};

/// How the simulator paces its steps.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum SimMode {
    /// Paced to the wall clock.
    Realtime,
    /// As fast as it can.
    Fast,
    /// Step N+1 only after every awaited controller answered step N.
    Lockstep,
}

/// The clock contract: whether a publisher with `rate_hz` is due at step `k` of a `physics_hz`
/// clock: at step 0 and whenever floor(t * rate) moves on. The simulator publishes by this rule,
/// and a controller in lockstep uses it to know which steps bring a camera frame.
pub fn due(k: u64, rate_hz: f64, physics_hz: u32) -> bool {
    let tick = |k: u64| ((k as f64 * rate_hz) / physics_hz as f64 + 1e-9).floor();
    k == 0 || tick(k) > tick(k - 1)
}

/// sim/clock: published every physics step (or at its configured rate).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SimClock {
    pub step: u64,
    /// Simulated seconds per wall-clock second, measured over the last second.
    pub real_time_factor: f32,
    pub mode: SimMode,
    pub physics_hz: f64,
}

impl Message for SimClock {
    const KIND: MessageKind = MessageKind::SimClock;
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum SimEventKind {
    ScenarioStart {
        name: String,
        seed: u64,
    },
    ScenarioEnd {
        reason: String,
        success: bool,
    },
    Collision {
        other_id: u32,
        relative_speed_mps: f64,
    },
    /// Lockstep waited longer than its timeout for these controllers.
    ControlTimeout {
        late: Vec<String>,
    },
}

/// sim/events: things that happen once.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SimEvent {
    pub kind: SimEventKind,
}

impl Message for SimEvent {
    const KIND: MessageKind = MessageKind::SimEvent;
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rates_tick_on_the_right_steps() {
        let steps = |rate| (0..100u64).filter(|k| due(*k, rate, 100)).count();
        assert_eq!(steps(100.0), 100);
        assert_eq!(steps(20.0), 20);
        assert!((0..100u64).filter(|k| due(*k, 20.0, 100)).all(|k| k % 5 == 0));
        assert_eq!(steps(30.0), 30);
    }
}
