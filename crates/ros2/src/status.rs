//! acc/status on a ROS 2 controller's behalf: the judge reads each run through acc/status (a
//! controller's contract, docs/node-contract.md), and an Ackermann command says nothing of a
//! mode or a lead. The bridge, the controller's side of the loop, reports what it knows: the
//! controller engaged in speed mode with the driver's settings sim/ego declares and the
//! acceleration its command asks for, no lead claimed. The judge then measures the gaps, time
//! to collision, comfort and braking from ground truth as for any controller; what needs a
//! claimed lead (time-gap RMS while following, unwarranted emergencies) has nothing to judge.

use std::sync::Arc;

use parking_lot::Mutex;

use slipstream_contract::bus::{Bus, CallbackSubscriber, Publisher, Received};
use slipstream_contract::msg::{AccMode, AccStatus, EgoInfo};
use slipstream_contract::topics;

use crate::error::Result;

/// acc/status per simulated second, as the controller SDK and slipstream-acc send it.
const STATUS_HZ: f64 = 20.0;
/// The settings before sim/ego arrives: slipstream-acc's defaults.
const DEFAULT_SET_SPEED_MPS: f64 = 25.0;
const DEFAULT_TIME_GAP_S: f64 = 1.8;

/// The status publisher, its clock and the driver's settings.
pub(crate) struct StatusOut {
    status: Publisher<AccStatus>,
    settings: Arc<Mutex<(f64, f64)>>,
    tick: Mutex<Option<i64>>,
    _ego: CallbackSubscriber,
}

impl StatusOut {
    pub(crate) async fn start(bus: &Bus) -> Result<StatusOut> {
        let settings = Arc::new(Mutex::new((DEFAULT_SET_SPEED_MPS, DEFAULT_TIME_GAP_S)));
        let s = settings.clone();
        let ego = bus
            .subscribe_with(topics::SIM_EGO, move |e: Received<EgoInfo>| {
                *s.lock() = (e.msg.set_speed_mps, e.msg.time_gap_s.unwrap_or(DEFAULT_TIME_GAP_S));
            })
            .await?;
        Ok(StatusOut { status: bus.publisher(topics::ACC_STATUS).await?, settings, tick: Mutex::new(None), _ego: ego })
    }

    /// acc/status for a command sent at `stamp_sim_ns` asking `accel_mps2`, when its tick is due.
    pub(crate) fn sent(&self, stamp_sim_ns: u64, accel_mps2: f64) {
        let tick = (stamp_sim_ns as f64 / 1e9 * STATUS_HZ + 1e-9).floor() as i64;
        if self.tick.lock().replace(tick) == Some(tick) {
            return;
        }
        let (set_speed_mps, time_gap_s) = *self.settings.lock();
        let status = AccStatus {
            mode: AccMode::Speed,
            set_speed_mps,
            time_gap_s,
            target_accel_mps2: accel_mps2,
            lead: None,
            warnings: Vec::new(),
        };
        if let Err(e) = self.status.put(stamp_sim_ns, &status) {
            tracing::warn!("acc/status: {e}");
        }
    }
}
