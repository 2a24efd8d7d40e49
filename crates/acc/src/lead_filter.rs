//! The lead estimate: a Kalman filter on the lead's gap, speed and acceleration, with
//! manoeuvre detection (speed innovations drifting one way, brake lamps coming on) and the
//! measured noise of its speed; and the perception source's measurement noise.

use nalgebra::{Matrix3, Vector3};

use super::settings::{AccSettings, PerceptionSource};
use super::tuning::FilterTuning;

/// The lead's gap, speed and acceleration, estimated by a Kalman filter on the relative
/// motion: the gap shrinks by the ego's travel (its speed is known exactly) and grows by the
/// lead's, whose acceleration is a random walk (white jerk). Perception measures the gap
/// and the relative speed. This smooths a camera's coarse range (one image row is metres
/// at 50 m) and gives the lead's acceleration for the threat assessment.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct LeadFilter {
    pub(super) id: u32,
    pub(super) t_s: f64,
    /// Gap (bumper to bumper), lead speed, lead acceleration.
    pub(super) x: Vector3<f64>,
    pub(super) p: Matrix3<f64>,
    /// Fading average of the normalised speed innovations: noise has both signs, a lead that
    /// starts (or stops) braking pushes it one way.
    pub(super) drift: f64,
    /// Fading mean square of the speed innovations while the lead is followed steadily (settled,
    /// no manoeuvre, lamps off): how noisy its speed reads, measured (m2/s2).
    pub(super) speed_noise_var: f64,
    /// When this lead was first taken: a new track's speed still converges (the tracker starts
    /// it at the ego's), so manoeuvres count only after `tuning.filter.settle_s`.
    pub(super) since_s: f64,
    /// Until then the lead counts as manoeuvring: its speed is followed closely.
    pub(super) manoeuvre_until_s: f64,
    /// Its brake lights were on in the last frame.
    pub(super) brake_lights: bool,
    /// When its brake lights came on, after being off for `tuning.filter.relit_s` at least, on a lead not yet
    /// seen slowing; when they were last seen lit.
    pub(super) lit_from_s: Option<f64>,
    pub(super) lit_last_s: f64,
    /// Since when its brake lights have been lit in every frame, while they are.
    pub(super) lit_run_from_s: f64,
    /// The frame it was last measured in.
    pub(super) seen_s: f64,
    /// Its tuning.
    pub(super) k: FilterTuning,
}

impl LeadFilter {
    pub(super) fn new(id: u32, t_s: f64, gap_m: f64, lead_speed_mps: f64, speed_sigma_mps: f64, n: &Noise) -> Self {
        let p = Matrix3::from_diagonal(&Vector3::new(
            n.gap_sigma(gap_m).powi(2),
            speed_sigma_mps.max(n.speed_steady_mps).powi(2),
            n.filter.new_lead_accel_sigma_mps2.get().powi(2),
        ));
        LeadFilter {
            id,
            t_s,
            x: Vector3::new(gap_m, lead_speed_mps, 0.0),
            p,
            drift: 0.0,
            speed_noise_var: speed_sigma_mps.max(n.speed_sigma(gap_m)).powi(2),
            since_s: t_s,
            manoeuvre_until_s: t_s,
            brake_lights: false,
            lit_from_s: None,
            lit_last_s: f64::NEG_INFINITY,
            lit_run_from_s: t_s,
            seen_s: t_s,
            k: n.filter,
        }
    }

    /// A measurement of the lead's speed. The filter assumes a slowly changing acceleration
    /// (smooth following behind a noisy camera range); when the speed innovations drift one
    /// way, the lead has changed what it does (a hard brake, say) and the acceleration's
    /// uncertainty is opened up, so the next frames measure it anew within a few frames
    /// instead of the seconds the slow model would take.
    ///
    /// `sigma` is the measurement's noise, used to detect a manoeuvre and while one lasts;
    /// otherwise the filter smooths with at least `steady_sigma`.
    pub(super) fn update_speed(&mut self, z: f64, sigma: f64, steady_sigma: f64) {
        // Against the measurement's own noise: the estimate's spread, wide while smoothing,
        // would hide the lead's first braking.
        let nu = (z - self.x[1]) / sigma;
        self.drift += self.k.manoeuvre_drift_gain.get() * (nu - self.drift);
        if self.settled() && self.t_s >= self.manoeuvre_until_s && !self.brake_lights {
            self.speed_noise_var += self.k.speed_noise_gain.get() * ((z - self.x[1]).powi(2) - self.speed_noise_var);
        }
        if self.settled() && self.drift.abs() > self.k.manoeuvre_drift.get() {
            tracing::debug!(id = self.id, t_s = self.t_s, drift = self.drift, "lead manoeuvre");
            self.manoeuvre();
        }
        let sigma = if self.t_s < self.manoeuvre_until_s || !self.settled() { sigma } else { sigma.max(steady_sigma) };
        self.update(1, z, sigma);
        if !self.settled() {
            self.unknown_accel();
        }
    }

    /// While a new lead's speed converges on what perception measures (from the ego's speed
    /// at first, over tenths of a second far away), that change is the measurement's, not
    /// the lead's: the acceleration stays unknown (zero, at its first uncertainty) until the
    /// lead is settled. Taken as the lead's, the convergence of a far car's speed reads as
    /// hard braking, and hard braking starts emergencies.
    pub(super) fn unknown_accel(&mut self) {
        self.x[2] = 0.0;
        for i in 0..2 {
            self.p[(i, 2)] = 0.0;
            self.p[(2, i)] = 0.0;
        }
        self.p[(2, 2)] = self.k.new_lead_accel_sigma_mps2.get().powi(2);
    }

    /// The lead changed what it does: the acceleration's uncertainty (and the speed's that
    /// builds over a window of it) is opened up and its speed followed closely for a while.
    pub(super) fn manoeuvre(&mut self) {
        self.p[(2, 2)] += self.k.manoeuvre_accel_sigma_mps2.get() * self.k.manoeuvre_accel_sigma_mps2.get();
        self.p[(1, 1)] += (self.k.manoeuvre_accel_sigma_mps2.get() * self.k.manoeuvre_window_s.get()).powi(2);
        self.drift = 0.0;
        self.manoeuvre_until_s = self.t_s + self.k.manoeuvre_hold_s.get();
    }

    /// The lead's brake lights in a frame: coming on, they start a manoeuvre at once (the
    /// pedal is pressed before the deceleration builds, and before the speed innovations
    /// could say so).
    pub(super) fn brake_lights(&mut self, on: bool) {
        // A brake application starting: not a frame or two of the lamps missed in a long one,
        // nor a driver dabbing the pedal to hold a speed (lamps flickering every few frames: a
        // car ending its braking 170 m ahead, each flash a new manoeuvre, had its speed followed
        // at the range's noise for seconds and read as braking at 13 m/s2).
        if on && !self.brake_lights && self.settled() && self.t_s - self.lit_last_s >= self.k.relit_s.get() {
            tracing::debug!(id = self.id, t_s = self.t_s, "lead brake lights on");
            self.manoeuvre();
            // Not for the lamps of a lead already seen slowing: its deceleration is measured,
            // the lamps add nothing to it.
            self.lit_from_s = (self.x[2] >= -self.k.slowing_mps2.get()).then_some(self.t_s);
        }
        if on && !self.brake_lights {
            self.lit_run_from_s = self.t_s;
        }
        if on {
            self.lit_last_s = self.t_s;
        }
        self.brake_lights = on;
    }

    /// How noisy its speed reads (`speed_noise_var`), m/s.
    pub(super) fn speed_noise_mps(&self) -> f64 {
        self.speed_noise_var.sqrt()
    }

    /// Its brake lights vouch for its estimated acceleration (`LeadNow::lamps_vouch`).
    pub(super) fn lamps_vouch(&self) -> bool {
        self.brake_lights
            && self.t_s - self.lit_run_from_s >= self.k.lit_held_s.get() - 1e-9
            && self.speed_noise_mps() <= self.k.lamps_vouch_noise_mps.get()
    }

    /// How long ago the lead's brake lights came on, while they are on.
    pub(super) fn lit_for_s(&self) -> Option<f64> {
        self.lit_from_s.filter(|_| self.brake_lights).map(|from| self.t_s - from)
    }

    /// Moves the estimate to `t_s` with the ego at `ego_speed_mps`.
    pub(super) fn predict(&mut self, t_s: f64, ego_speed_mps: f64, jerk_sigma: f64) {
        let dt = t_s - self.t_s;
        if dt <= 0.0 {
            return;
        }
        // A lead whose brake lights came on builds its deceleration: for the manoeuvre's
        // hold its acceleration may change as fast as a brake application makes it.
        let jerk_sigma = if self.brake_lights && self.t_s < self.manoeuvre_until_s {
            jerk_sigma.max(self.k.braking_jerk_sigma_mps3.get())
        } else {
            jerk_sigma
        };
        self.t_s = t_s;
        let f = Matrix3::new(1.0, dt, dt * dt / 2.0, 0.0, 1.0, dt, 0.0, 0.0, 1.0);
        self.x = f * self.x;
        self.x[0] -= ego_speed_mps * dt;
        // A stopped lead does not roll backwards.
        if self.x[1] < 0.0 {
            self.x[1] = 0.0;
            self.x[2] = self.x[2].max(0.0);
        }
        let (d2, d3, d4, d5) = (dt * dt, dt.powi(3), dt.powi(4), dt.powi(5));
        let q = Matrix3::new(d5 / 20.0, d4 / 8.0, d3 / 6.0, d4 / 8.0, d3 / 3.0, d2 / 2.0, d3 / 6.0, d2 / 2.0, dt)
            * (jerk_sigma * jerk_sigma);
        self.p = f * self.p * f.transpose() + q;
    }

    /// Followed long enough for its speed and acceleration to mean something.
    pub(super) fn settled(&self) -> bool {
        self.t_s - self.since_s >= self.k.settle_s.get()
    }

    /// A scalar measurement of state component `i`.
    pub(super) fn update(&mut self, i: usize, z: f64, sigma: f64) {
        let s = self.p[(i, i)] + sigma * sigma;
        let k: Vector3<f64> = self.p.column(i) / s;
        self.x += k * (z - self.x[i]);
        let mut kh = Matrix3::zeros();
        kh.set_column(i, &k);
        self.p = (Matrix3::identity() - kh) * self.p;
    }
}

/// Measurement noise of the perception source.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Noise {
    pub(super) gap_base_m: f64,
    pub(super) gap_per_m2: f64,
    pub(super) speed_base_mps: f64,
    pub(super) speed_per_m2: f64,
    /// Outside manoeuvres the speed is smoothed as if this noisy.
    pub(super) speed_steady_mps: f64,
    pub(super) jerk_sigma_mps3: f64,
    /// How far the lead's estimated deceleration may overshoot the true one.
    pub(super) hard_braking_margin_mps2: f64,
    /// The filter's tuning.
    pub(super) filter: FilterTuning,
}

/// The noise the filter assumes for ground truth's gap and speed (m, m/s): the truth is exact,
/// and a floor keeps the filter's covariance positive (a zero measurement noise makes its gain
/// 1 and its covariance singular).
const GROUND_TRUTH_SIGMA: f64 = 0.05;

impl Noise {
    /// The perception source's noise, from the settings: the camera's from the estimator
    /// group; ground truth's exact measurements, which the filter follows.
    pub(super) fn of(s: &AccSettings) -> Self {
        let e = &s.estimator;
        match s.perception {
            PerceptionSource::Camera => Noise {
                gap_base_m: e.gap_sigma_m,
                gap_per_m2: e.gap_sigma_per_m2,
                speed_base_mps: e.speed_sigma_mps,
                speed_per_m2: e.speed_sigma_per_m2,
                speed_steady_mps: e.steady_speed_sigma_mps,
                jerk_sigma_mps3: e.lead_jerk_sigma_mps3,
                hard_braking_margin_mps2: e.hard_braking_margin_mps2,
                filter: s.tuning.filter,
            },
            PerceptionSource::GroundTruth => Noise {
                gap_base_m: GROUND_TRUTH_SIGMA,
                gap_per_m2: 0.0,
                speed_base_mps: GROUND_TRUTH_SIGMA,
                speed_per_m2: 0.0,
                speed_steady_mps: GROUND_TRUTH_SIGMA,
                jerk_sigma_mps3: e.lead_jerk_sigma_mps3,
                hard_braking_margin_mps2: s.tuning.belief.ground_truth_hard_braking_margin_mps2.get(),
                filter: s.tuning.filter,
            },
        }
    }

    pub(super) fn gap_sigma(&self, gap_m: f64) -> f64 {
        self.gap_base_m + self.gap_per_m2 * gap_m.max(0.0).powi(2)
    }

    pub(super) fn speed_sigma(&self, gap_m: f64) -> f64 {
        self.speed_base_mps + self.speed_per_m2 * gap_m.max(0.0).powi(2)
    }

    /// The steady smoothing of the lead's speed at this gap: the setting's from
    /// `tuning.filter.steady_full_gap_m` on, less nearer, with the square of the gap (as the range's error),
    /// never below the measurement's own noise.
    pub(super) fn speed_steady(&self, gap_m: f64) -> f64 {
        let share = (gap_m.max(0.0) / self.filter.steady_full_gap_m.get()).powi(2).min(1.0);
        (self.speed_steady_mps * share).max(self.speed_sigma(gap_m))
    }
}
