//! A run with several controlled vehicles, judged car by car: each ego's topics recorded in
//! its namespace and judged as a run with one ego is ([`super::judge::judge_ego`]), so `eval
//! acc` holds every car of a platoon to the same aims as the only car of a scenario.

use serde::{Deserialize, Serialize};

use super::judge::{judge_ego, Judged};
use super::metrics::Metrics;
use super::trace::{Recorded, Recorder};
use crate::error::{Error, Result};
use slipstream_launch::LoopRun;
use slipstream_sim::{Scenario, SimReport};

/// One ego's run in a scenario with several.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct EgoResult {
    /// Its namespace under the run's.
    pub namespace: String,
    pub metrics: Metrics,
    /// Steps the simulator waited out without this ego's controllers' answers.
    pub lockstep_timeouts: u64,
}

impl EgoResult {
    pub fn passed(&self) -> bool {
        self.metrics.pass && self.lockstep_timeouts == 0
    }
}

/// Recorders of the run's ego, or of each ego in its namespace when there are several; the
/// first is the first ego's.
pub(crate) async fn record_each(lp: &LoopRun) -> Result<Vec<(String, Recorder)>> {
    if lp.spec().egos.is_empty() {
        return Ok(vec![(String::new(), Recorder::start(lp.bus()).await?)]);
    }
    let mut recorders = Vec::new();
    for ego in &lp.spec().egos {
        recorders.push((ego.namespace.clone(), Recorder::start(&lp.bus().scoped(&ego.namespace)?).await?));
    }
    Ok(recorders)
}

/// Each ego judged on what was recorded in its namespace, in the egos' order.
pub(crate) fn judge_all(recorded: &[(String, Recorded)], scenario: &Scenario, sim: &SimReport) -> Vec<Judged> {
    recorded.iter().enumerate().map(|(k, (_, rec))| judge_ego(rec, scenario, k, Some(sim), "stopped")).collect()
}

/// The results of several egos (`judged` by [`judge_all`]); empty for a run with one ego. A
/// car too short-lived to judge is an error naming it.
pub fn results(recorded: &[(String, Recorded)], judged: &[Judged], sim: &SimReport) -> Result<Vec<EgoResult>> {
    if recorded.len() < 2 {
        return Ok(Vec::new());
    }
    let mut egos = Vec::new();
    for (k, ((namespace, _), judged)) in recorded.iter().zip(judged).enumerate() {
        let samples = judged.trace.samples.len();
        let metrics = judged
            .metrics
            .clone()
            .ok_or_else(|| Error::Unjudged(format!("{namespace}: recorded only {samples} states")))?;
        let lockstep_timeouts = sim.egos.get(k).map_or(0, |e| e.lockstep_timeouts);
        egos.push(EgoResult { namespace: namespace.clone(), metrics, lockstep_timeouts });
    }
    Ok(egos)
}
