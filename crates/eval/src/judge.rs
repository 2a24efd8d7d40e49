//! A finished run of the loop, judged: the one tail of `slipstream up` and `eval acc`
//! (recording -> [`Trace`] -> [`Metrics`]). It stands apart from the trace so that the trace
//! does not depend on the metrics made from it.

use super::metrics::Metrics;
use super::trace::{build_trace, Recorded, Trace};
use slipstream_acc::AccSettings;
use slipstream_model::vehicle::VehicleParams;
use slipstream_sim::{Scenario, SimReport};

/// Fewer samples than this and a run is not judged (it hardly ran).
pub(crate) const MIN_SAMPLES: usize = 10;

/// A finished run of the loop on the bus, judged: the one tail of `slipstream up` and
/// `eval acc` (recording -> trace -> metrics).
#[derive(Debug, Clone)]
pub struct Judged {
    pub trace: Trace,
    /// None when the run has fewer than [`MIN_SAMPLES`] samples.
    pub metrics: Option<Metrics>,
}

/// Builds the trace of `scenario` from what was recorded and the simulator's report (its
/// collision count and end reason win over the recorder's, which may miss the last events),
/// and judges it. `end_if_unknown` names the end when the simulator said nothing.
pub fn judge(rec: &Recorded, scenario: &Scenario, sim: Option<&SimReport>, end_if_unknown: &str) -> Judged {
    judge_ego(rec, scenario, 0, sim, end_if_unknown)
}

/// [`judge`] for ego `k` of a scenario's several, on its own record (its namespace's
/// topics): its class, its collisions in the simulator's report (with another ego too).
pub fn judge_ego(
    rec: &Recorded,
    scenario: &Scenario,
    k: usize,
    sim: Option<&SimReport>,
    end_if_unknown: &str,
) -> Judged {
    let ego = VehicleParams::of_class(scenario.egos()[k].class.into());
    let front_m = ego.size_m[0] - ego.rear_overhang_m;
    let mut trace = build_trace(rec, front_m, AccSettings::default().standstill_m);
    let sim_collisions = sim.map_or(0, |s| s.egos.get(k).map_or(s.ego_collisions, |e| e.collisions));
    trace.collisions = sim_collisions.max(rec.collisions);
    trace.traffic_collisions = sim.map_or(0, |s| s.traffic_collisions);
    trace.min_gap_aim_m = scenario.expect.min_gap_m;
    trace.braking_warranted = scenario.expect.braking;
    trace.end = sim.and_then(|s| s.end.as_ref()).map_or_else(|| end_if_unknown.to_string(), |e| e.reason.clone());
    let metrics = (trace.samples.len() > MIN_SAMPLES).then(|| Metrics::of(&trace));
    Judged { trace, metrics }
}
