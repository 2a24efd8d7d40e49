//! The ACC's decisions, free of any I/O: the wiring of its parts, each in a file of its own
//! with one job. Per perception frame, lead selection ([`super::select`]: the lane ahead,
//! each track's place in it, the lead, the lead estimate). Per control step: the lead belief
//! ([`super::belief`]: what the lead plausibly does), the threat ([`super::threat`]), the
//! decision between comfort braking and an emergency ([`super::decision`]), the comfort
//! command ([`super::command`]: spacing law, jerk limit, release) and the low-level loop
//! ([`super::low_level`]: throttle and brake). Every behavioural number is a setting
//! (config/acc.json5, `tuning` among them). The node (`super::node`) feeds it; tests drive it
//! directly.
//!
//! Units: seconds of simulated time, metres, m/s, m/s2. The ego's body frame: x forward from the
//! rear axle, y left.

use super::belief::{Around, Hypotheses, LeadBelief};
use super::command::{Command, Inputs};
use super::decision::{comfort_brake_mps2, warns, Decision, Now};
use super::ego::EgoNow;
use super::lead_filter::Noise;
use super::low_level::LowLevel;
use super::objects::PerceptionFrame;
use super::select::LeadSelect;
use super::settings::{AccSettings, SET_SPEED_RANGE_MPS, TIME_GAP_RANGE_S};
use slipstream_contract::msg::{AccCommand, AccMode, AccStatus, AccWarning, LeadInfo, RoadSpec};
use slipstream_model::road::Road;
use slipstream_model::vehicle::VehicleParams;

/// What one control step decided.
#[derive(Debug, Clone, PartialEq)]
pub struct Output {
    pub throttle: f32,
    pub brake: f32,
    pub status: AccStatus,
}

/// The longest step the controller integrates over, s (jerk limit, integrator, filters): after
/// a pause in its inputs (a stale speed, a paused simulator) it goes on from where it was
/// instead of jumping by the whole pause. 20 speed periods at 100 Hz.
const MAX_STEP_S: f64 = 0.2;

pub struct Controller {
    s: AccSettings,
    params: VehicleParams,
    enabled: bool,
    set_speed_mps: f64,
    time_gap_s: f64,
    select: LeadSelect,
    last_t_s: Option<f64>,
    decision: Decision,
    command: Command,
    low_level: LowLevel,
}

impl Controller {
    pub fn new(settings: AccSettings) -> Self {
        let noise = Noise::of(&settings);
        Controller {
            params: settings.vehicle.params(),
            enabled: settings.enabled,
            set_speed_mps: settings.set_speed_mps,
            time_gap_s: settings.time_gap_s,
            s: settings,
            select: LeadSelect::new(noise),
            last_t_s: None,
            decision: Decision::default(),
            command: Command::default(),
            low_level: LowLevel::default(),
        }
    }

    pub fn settings(&self) -> &AccSettings {
        &self.s
    }

    pub fn set_speed_mps(&self) -> f64 {
        self.set_speed_mps
    }

    pub fn time_gap_s(&self) -> f64 {
        self.time_gap_s
    }

    pub fn enabled(&self) -> bool {
        self.enabled
    }

    /// Applies acc/command; returns what was refused (a time gap outside the allowed range is
    /// clamped into it).
    pub fn command(&mut self, cmd: &AccCommand) -> Option<String> {
        let mut note = None;
        if let Some(e) = cmd.enable {
            if e != self.enabled {
                tracing::info!(enabled = e, "acc/command: {}", if e { "engaged" } else { "disengaged" });
            }
            self.enabled = e;
            if e {
                self.decision.emergency = false;
            }
        }
        if let Some(v) = cmd.set_speed_mps {
            self.set_speed_mps = v.clamp(*SET_SPEED_RANGE_MPS.start(), *SET_SPEED_RANGE_MPS.end());
            tracing::info!(set_speed_mps = self.set_speed_mps, "acc/command: set speed");
        }
        if let Some(h) = cmd.time_gap_s {
            let clamped = h.clamp(*TIME_GAP_RANGE_S.start(), *TIME_GAP_RANGE_S.end());
            if clamped != h {
                note = Some(format!("time gap {h} s is outside 0.8..3.0 s; using {clamped} s"));
            }
            self.time_gap_s = clamped;
            tracing::info!(time_gap_s = self.time_gap_s, "acc/command: time gap");
        }
        note
    }

    /// Takes the road's map (sim/road): from now on the lane ahead comes from it wherever the
    /// ego's pose is known and on the road.
    pub fn set_road(&mut self, spec: &RoadSpec) {
        if self.select.road.as_ref().is_some_and(|r| r.spec() == spec) {
            return;
        }
        tracing::info!(lanes = spec.lanes, curves = spec.curves.len(), "road map received: lanes ahead from it");
        self.select.set_road(Road::new(spec.clone()));
    }

    /// Whether the road's map has come (sim/road).
    pub(crate) fn has_road(&self) -> bool {
        self.select.road.is_some()
    }

    /// Takes a perception frame: lead selection and the lead estimate ([`super::select`]).
    pub fn perceive(&mut self, frame: &PerceptionFrame, ego: &EgoNow) {
        self.select.perceive(&self.s, frame, ego);
    }

    /// One control step. `warnings` are the node's findings about its inputs (stale speed or
    /// perception, perception lost); any of them puts the ACC in Stale mode.
    pub fn step(&mut self, ego: &EgoNow, warnings: &[AccWarning]) -> Output {
        let dt = self.last_t_s.map_or(0.0, |t| (ego.t_s - t).clamp(0.0, MAX_STEP_S));
        self.last_t_s = Some(ego.t_s);
        let v = ego.speed_mps.max(0.0);
        let mut warnings: Vec<AccWarning> = warnings.to_vec();
        let stale = !warnings.is_empty();

        let lead = self.belief(ego.t_s, v, stale);
        let hypotheses = lead.map(|l| self.hypotheses(&l, ego.t_s, v));
        let threat = hypotheses.map(|h| h.threat());
        if threat.is_some_and(|t| warns(&self.s, &t, v, self.command.accel_cmd)) {
            warnings.push(AccWarning::ForwardCollision);
        }
        let (mode, accel) = if !self.enabled {
            self.decision.clear();
            (AccMode::Off, 0.0)
        } else if stale {
            self.decision.clear();
            // From the last command to the stale deceleration within the jerk limit, from either
            // side: no jolt when perception drops out for a moment (a burst of lost frames).
            let (from, step) = (self.command.accel_cmd, self.s.limits.jerk_mps3 * dt);
            (AccMode::Stale, (-self.s.stale.decel_mps2).clamp(from - step, from + step))
        } else {
            self.drive(lead, hypotheses, v, ego.t_s, dt)
        };
        // The actuators lag: ask for the target plus lag x its rate of change, so the applied
        // acceleration follows a ramping target instead of trailing it (a jump, as into an
        // emergency, is not anticipated beyond twice the jerk limit; a release up to its jerk,
        // so that it ends where the target does instead of overshooting it).
        let down = 2.0 * self.s.limits.jerk_mps3;
        let up = down.max(self.s.tuning.command.release_jerk_mps3.get());
        let from = self.command.accel_cmd;
        let rate = if dt > 0.0 { ((accel - from) / dt).clamp(-down, up) } else { 0.0 };
        let lag_lead = self.params.actuator_lag_s * rate;
        self.command.set(accel, mode, lead.as_ref());
        let (throttle, brake) =
            self.low_level.actuate(&self.s, &self.params, mode, accel, lag_lead, v, ego.accel_mps2, dt);
        let status = AccStatus {
            mode,
            set_speed_mps: self.set_speed_mps,
            time_gap_s: self.time_gap_s,
            target_accel_mps2: accel,
            lead: lead.map(|l| LeadInfo {
                id: l.id,
                gap_m: l.gap_m,
                desired_gap_m: self.s.standstill_m + self.time_gap_s * v,
                relative_speed_mps: l.speed_mps - v,
                ttc_s: threat.and_then(|t| t.ttc_s),
            }),
            warnings,
        };
        Output { throttle, brake, status }
    }

    /// Engaged with fresh inputs: the decision, then an emergency's deceleration or the comfort
    /// command.
    fn drive(&mut self, lead: Option<LeadBelief>, h: Option<Hypotheses>, v: f64, t_s: f64, dt: f64) -> (AccMode, f64) {
        self.decision.hard_lead = lead.filter(|_| h.is_some_and(|h| h.likely.is_some())).map(|l| l.id);
        let now = Now { settings: &self.s, speed_mps: v, accel_cmd_mps2: self.command.accel_cmd, t_s };
        self.decision.update(h.as_ref(), &now);
        if let Some(h) = h.filter(|_| self.decision.emergency) {
            return (AccMode::Emergency, -self.decision.decel(&self.s, &h.threat(), v));
        }
        let time_gap_s = self.time_gap_s;
        let brake_at_least_mps2 = h.zip(lead).and_then(|(h, l)| comfort_brake_mps2(&h, &l, &self.s, v, time_gap_s));
        let set_speed_mps = self.set_speed_mps;
        let inputs = Inputs { s: &self.s, v, set_speed_mps, time_gap_s, lead, brake_at_least_mps2, dt };
        self.command.comfort(&inputs)
    }

    /// The lead's hypotheses this step, with what it hides or reveals as lead selection sees it.
    fn hypotheses(&self, lead: &LeadBelief, t_s: f64, v: f64) -> Hypotheses {
        let k = &self.s.tuning.threat;
        let confirm_s = self.s.tuning.decision.confirm_s.get();
        let around = Around {
            revealed: self.select.revealed(k, t_s, v),
            revealed_confirmed: self.select.revealed_for(k, t_s, v, confirm_s),
        };
        let was_hard = self.decision.hard_lead == Some(lead.id);
        let margin = self.select.noise.hard_braking_margin_mps2;
        lead.hypotheses(&self.s, v, self.time_gap_s, around, (margin, was_hard))
    }

    /// The lead believed now: its estimate moved on to `t_s`. None while stale: the
    /// watchdog's clock is a guess, and the estimate is not used then (it catches up when
    /// fresh data return).
    fn belief(&mut self, t_s: f64, v: f64, stale: bool) -> Option<LeadBelief> {
        if stale {
            return None;
        }
        let jerk_sigma = self.select.noise.jerk_sigma_mps3;
        let f = self.select.lead.as_mut()?;
        f.predict(t_s, v, jerk_sigma);
        let l = LeadBelief::of(f);
        tracing::trace!(
            t_s,
            gap_m = l.gap_m,
            speed_mps = l.speed_mps,
            accel_mps2 = l.accel_mps2,
            brake_lights = l.brake_lights,
            speed_noise_mps = f.speed_noise_mps(),
            last_target_mps2 = self.command.accel_cmd,
            "lead"
        );
        Some(l)
    }
}
