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
