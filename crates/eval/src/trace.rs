//! The record of a run: what a recorder kept from the bus ([`Recorder`]: vehicle/state,
//! acc/status, objects, collisions), and the [`Trace`] built from it: one [`Sample`] per
//! vehicle/state message (every physics step by default) with the ego's motion, the ACC's
//! status and the true lead in the ego's lane. Metrics, plots and trace.csv are made from a
//! trace, whichever way the loop ran (`up`, `eval acc`, the in-process loop).

use std::path::Path;
use std::sync::Arc;

use crate::error::{Error, Result};
use parking_lot::Mutex;
use serde::Serialize;

use slipstream_contract::bus::{Bus, CallbackSubscriber, Received};
use slipstream_contract::msg::{SimEvent, SimEventKind};
use slipstream_contract::topics;
use slipstream_sim::scenario::Warranted;

use slipstream_contract::msg::{AccMode, AccStatus, GroundTruthObjects, VehicleState};

/// The true lead: the nearest vehicle ahead whose centre is in the ego's lane.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct TruthLead {
    pub id: u32,
    /// Bumper to bumper.
    pub gap_m: f64,
    /// Lead speed minus ego speed along ego x.
    pub relative_speed_mps: f64,
    /// The lead's own speed. Judged on rather than the ego's speed plus the relative speed:
    /// objects come at the camera's rate and states at the speed messages', so that sum mixed
    /// two instants and jittered by the ego's acceleration times the gap between them (0.05 m/s
    /// at 1 m/s2 and 20 Hz: 0.1 m/s2 of lead acceleration over the swing's 0.5 s window).
    pub speed_mps: f64,
}

/// The nearest two vehicles ahead whose centres are in the ego's lane: the true lead and the
/// next beyond it.
pub(crate) fn truth_in_lane(
    gt: &GroundTruthObjects,
    ego_lane: i32,
    ego_front_m: f64,
) -> (Option<TruthLead>, Option<TruthLead>) {
    let mut ahead: Vec<&slipstream_contract::msg::GroundTruthObject> =
        gt.objects.iter().filter(|o| o.lane == ego_lane && ego_lane >= 0 && o.position_in_ego_m[0] > 0.0).collect();
    ahead.sort_by(|a, b| a.position_in_ego_m[0].total_cmp(&b.position_in_ego_m[0]));
    let of = |o: &&slipstream_contract::msg::GroundTruthObject| TruthLead {
        id: o.id,
        gap_m: o.position_in_ego_m[0] - ego_front_m,
        relative_speed_mps: o.velocity_in_ego_mps[0],
        speed_mps: o.velocity_in_world_mps[0].hypot(o.velocity_in_world_mps[1]),
    };
    (ahead.first().map(of), ahead.get(1).map(of))
}

#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Sample {
    pub t_s: f64,
    pub speed_mps: f64,
    pub accel_mps2: f64,
    pub mode: AccMode,
    pub target_accel_mps2: f64,
    pub set_speed_mps: f64,
    pub time_gap_s: f64,
    /// The gap the ACC measured to its lead.
    pub acc_gap_m: Option<f64>,
    pub truth: Option<TruthLead>,
    /// The next vehicle in the ego's lane beyond the true lead.
    pub beyond: Option<TruthLead>,
}

impl Sample {
    /// `truth`: the true lead and the next vehicle in the lane beyond it.
    pub fn new(
        t_s: f64,
        state: &VehicleState,
        status: &AccStatus,
        truth: (Option<TruthLead>, Option<TruthLead>),
    ) -> Self {
        Sample {
            t_s,
            speed_mps: state.speed_mps,
            accel_mps2: state.acceleration_in_body_mps2[0],
            mode: status.mode,
            target_accel_mps2: status.target_accel_mps2,
            set_speed_mps: status.set_speed_mps,
            time_gap_s: status.time_gap_s,
            acc_gap_m: status.lead.map(|l| l.gap_m),
            truth: truth.0,
            beyond: truth.1,
        }
    }

    /// The true lead's speed, when there is one.
    pub fn lead_speed_mps(&self) -> Option<f64> {
        self.truth.map(|t| t.speed_mps)
    }
}

/// One run of a scenario.
#[derive(Debug, Clone, Default, Serialize)]
pub struct Trace {
    pub standstill_m: f64,
    pub samples: Vec<Sample>,
    /// The ego's collisions.
    pub collisions: u64,
    /// Collisions among traffic vehicles.
    pub traffic_collisions: u64,
    /// Why the scenario ended.
    pub end: String,
    /// The smallest gap the scenario asks to keep (its `expect.min_gap_m`); None: any gap > 0.
    pub min_gap_aim_m: Option<f64>,
    /// The most braking the scenario declares warranted (its `expect.braking`); None: not
    /// declared.
    pub braking_warranted: Option<Warranted>,
}

/// What the recorder keeps, in arrival order.
#[derive(Default)]
pub struct Recorded {
    pub states: Vec<Received<VehicleState>>,
    pub statuses: Vec<Received<AccStatus>>,
    pub objects: Vec<Received<GroundTruthObjects>>,
    pub collisions: u64,
}

/// Records vehicle/state, acc/status, objects and the collisions on sim/events: what a run is
/// judged by.
pub struct Recorder {
    pub rec: Arc<Mutex<Recorded>>,
    subs: [CallbackSubscriber; 4],
}

impl Recorder {
    pub async fn start(bus: &Bus) -> Result<Recorder> {
        let rec = Arc::new(Mutex::new(Recorded::default()));
        let r = rec.clone();
        let s1 = bus.subscribe_with(topics::VEHICLE_STATE, move |m| r.lock().states.push(m)).await?;
        let r = rec.clone();
        let s2 = bus.subscribe_with(topics::ACC_STATUS, move |m| r.lock().statuses.push(m)).await?;
        let r = rec.clone();
        let s3 = bus.subscribe_with(topics::OBJECTS, move |m| r.lock().objects.push(m)).await?;
        let r = rec.clone();
        let s4 = bus
            .subscribe_with(topics::SIM_EVENTS, move |m: Received<SimEvent>| {
                if matches!(m.msg.kind, SimEventKind::Collision { .. }) {
                    r.lock().collisions += 1;
                }
            })
            .await?;
        Ok(Recorder { rec, subs: [s1, s2, s3, s4] })
    }

    /// What the recorder received, topic by topic: a message lost on the way leaves a gap in
    /// the trace the run is judged by, so the run's report lists these beside the nodes' inputs.
    pub fn inputs(&self) -> Vec<slipstream_contract::bus::StatsSnapshot> {
        self.subs.iter().map(|s| s.stats().snapshot()).collect()
    }

    /// Everything recorded so far, leaving the recorder empty.
    pub fn take(&self) -> Recorded {
        std::mem::take(&mut *self.rec.lock())
    }
}

/// One sample per recorded state, with the newest status and ground truth at its time.
pub(crate) fn build_trace(rec: &Recorded, ego_front: f64, standstill_m: f64) -> Trace {
    let mut states: Vec<&Received<VehicleState>> = rec.states.iter().collect();
    states.sort_by_key(|r| r.header.stamp_sim_ns);
    states.dedup_by_key(|r| r.header.stamp_sim_ns);
    let mut statuses: Vec<&Received<AccStatus>> = rec.statuses.iter().collect();
    statuses.sort_by_key(|r| r.header.stamp_sim_ns);
    let mut objects: Vec<&Received<GroundTruthObjects>> = rec.objects.iter().collect();
    objects.sort_by_key(|r| r.header.stamp_sim_ns);
    let (mut si, mut oi) = (0usize, 0usize);
    let mut samples = Vec::with_capacity(states.len());
    for st in states {
        let t = st.header.stamp_sim_ns;
        while si + 1 < statuses.len() && statuses[si + 1].header.stamp_sim_ns <= t {
            si += 1;
        }
        while oi + 1 < objects.len() && objects[oi + 1].header.stamp_sim_ns <= t {
            oi += 1;
        }
        let Some(status) = statuses.get(si).filter(|s| s.header.stamp_sim_ns <= t) else { continue };
        let truth = objects.get(oi).filter(|o| o.header.stamp_sim_ns <= t).map_or((None, None), |o| {
            let (lead, beyond) = truth_in_lane(&o.msg, st.msg.lane, ego_front);
            // Moved on from the frame's time at the relative speed.
            let ahead = (t - o.header.stamp_sim_ns) as f64 / 1e9;
            let on = |v: TruthLead| TruthLead { gap_m: v.gap_m + v.relative_speed_mps * ahead, ..v };
            (lead.map(on), beyond.map(on))
        });
        samples.push(Sample::new(t as f64 / 1e9, &st.msg, &status.msg, truth));
    }
    Trace { standstill_m, samples, ..Default::default() }
}

impl Trace {
    /// Writes the trace as CSV: one row per vehicle/state, what the plot shows, for a
    /// spreadsheet or pandas. Values rounded to what the loop resolves (ms, mm, mm/s); an
    /// unknown gap is an empty cell.
    pub fn write_csv(&self, path: &Path) -> Result<()> {
        /// One row of trace.csv; the field names are the header.
        #[derive(Serialize)]
        struct Row {
            t_s: f64,
            speed_mps: f64,
            accel_mps2: f64,
            acc_mode: AccMode,
            target_accel_mps2: f64,
            set_speed_mps: f64,
            time_gap_s: f64,
            acc_gap_m: Option<f64>,
            truth_gap_m: Option<f64>,
            truth_lead_speed_mps: Option<f64>,
        }
        let r = |v: f64, digits: i32| (v * 10f64.powi(digits)).round() / 10f64.powi(digits);
        let csv_error = |source| Error::Csv { path: path.to_path_buf(), source };
        let mut out = csv::Writer::from_path(path).map_err(csv_error)?;
        for x in &self.samples {
            out.serialize(Row {
                t_s: r(x.t_s, 3),
                speed_mps: r(x.speed_mps, 4),
                accel_mps2: r(x.accel_mps2, 4),
                acc_mode: x.mode,
                target_accel_mps2: r(x.target_accel_mps2, 4),
                set_speed_mps: r(x.set_speed_mps, 3),
                time_gap_s: r(x.time_gap_s, 3),
                acc_gap_m: x.acc_gap_m.map(|v| r(v, 4)),
                truth_gap_m: x.truth.map(|t| r(t.gap_m, 4)),
                truth_lead_speed_mps: x.lead_speed_mps().map(|v| r(v, 4)),
            })
            .map_err(csv_error)?;
        }
        out.flush().map_err(Error::file("write", path))
    }
}
