//! Adaptive cruise control status and commands.

use serde::{Deserialize, Serialize};

use super::{Message, MessageKind, Unsound};

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum AccMode {
    /// Disabled by command: passes no throttle.
    Off,
    /// Holding the set speed, no lead vehicle.
    Speed,
    /// Following a lead vehicle at the time gap.
    Follow,
    /// Inputs too old: easing to a soft deceleration within the jerk limit.
    Stale,
    /// Time to collision below threshold: braking at the vehicle's limit.
    Emergency,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum AccWarning {
    ForwardCollision,
    StaleSpeed,
    StalePerception,
    PerceptionLost,
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct LeadInfo {
    pub id: u32,
    pub gap_m: f64,
    pub desired_gap_m: f64,
    pub relative_speed_mps: f64,
    /// Time to collision; None when not closing in.
    pub ttc_s: Option<f64>,
}

/// acc/status
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AccStatus {
    pub mode: AccMode,
    pub set_speed_mps: f64,
    pub time_gap_s: f64,
    pub target_accel_mps2: f64,
    pub lead: Option<LeadInfo>,
    pub warnings: Vec<AccWarning>,
}

impl Message for AccStatus {
    const KIND: MessageKind = MessageKind::AccStatus;
}

/// acc/command: each present field changes that setting; absent fields are left alone.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct AccCommand {
    pub enable: Option<bool>,
    pub set_speed_mps: Option<f64>,
    pub time_gap_s: Option<f64>,
}

impl Message for AccCommand {
    const KIND: MessageKind = MessageKind::AccCommand;
    fn check(&self) -> Result<(), Unsound> {
        if let Some(v) = self.set_speed_mps {
            if !(v.is_finite() && v >= 0.0) {
                return Err(Unsound(format!("set_speed_mps {v} must be a finite value >= 0")));
            }
        }
        if let Some(h) = self.time_gap_s {
            if !(h.is_finite() && h > 0.0) {
                return Err(Unsound(format!("time_gap_s {h} must be a finite value > 0")));
            }
        }
        Ok(())
    }
}

/// The AccStatus of docs/wire-format.md's byte example.
pub fn example_status() -> AccStatus {
    AccStatus {
        mode: AccMode::Follow,
        set_speed_mps: 30.0,
        time_gap_s: 1.8,
        target_accel_mps2: -0.5,
        lead: Some(LeadInfo { id: 3, gap_m: 27.75, desired_gap_m: 54.5, relative_speed_mps: -2.5, ttc_s: Some(11.1) }),
        warnings: vec![],
    }
}
