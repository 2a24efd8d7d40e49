//! A simulator the loop does not start (`up --sim external`): the Python reference simulator,
//! a CARLA or CoppeliaSim adapter, slipstream-sim on another PC. The loop knows it only by
//! its messages (docs/simulator-contract.md): it is there once vehicle/speed arrives, and
//! over when it says so on sim/events, when the simulated time asked for has passed, or when
//! it goes silent.

use std::sync::Arc;
use std::time::{Duration, Instant};

use crate::error::{Error, Result};
use parking_lot::Mutex;

use slipstream_contract::bus::{Bus, CallbackSubscriber, Received};
use slipstream_contract::msg::{SimEvent, SimEventKind, Speed};
use slipstream_contract::topics;

/// An external simulator that sends nothing for this long has stopped.
pub(crate) const SILENCE: Duration = Duration::from_secs(5);

#[derive(Default)]
struct Seen {
    /// Wall clock of the newest vehicle/speed.
    last: Option<Instant>,
    /// Its simulated time, and the first one seen.
    newest_sim_ns: u64,
    first_sim_ns: Option<u64>,
    /// ScenarioEnd's reason.
    ended: Option<String>,
}

/// What the loop follows of an external simulator.
pub struct ExternalSim {
    seen: Arc<Mutex<Seen>>,
    speed_key: String,
    _subs: [CallbackSubscriber; 2],
}

impl ExternalSim {
    /// Follows vehicle/speed and sim/events on `bus`.
    pub async fn watch(bus: &Bus) -> Result<ExternalSim> {
        let seen: Arc<Mutex<Seen>> = Arc::default();
        let s = seen.clone();
        let speed = bus
            .subscribe_with(topics::VEHICLE_SPEED, move |r: Received<Speed>| {
                let mut s = s.lock();
                s.last = Some(Instant::now());
                s.newest_sim_ns = s.newest_sim_ns.max(r.header.stamp_sim_ns);
                s.first_sim_ns.get_or_insert(r.header.stamp_sim_ns);
            })
            .await?;
        let s = seen.clone();
        let events = bus
            .subscribe_with(topics::SIM_EVENTS, move |r: Received<SimEvent>| {
                if let SimEventKind::ScenarioEnd { reason, .. } = r.msg.kind {
                    s.lock().ended = Some(reason);
                }
            })
            .await?;
        let speed_key = bus.topics().key(topics::VEHICLE_SPEED.topic).to_string();
        Ok(ExternalSim { seen, speed_key, _subs: [speed, events] })
    }

    /// Waits until the simulator's first vehicle/speed, at most `timeout`.
    pub async fn wait_started(&self, timeout: Duration) -> Result<()> {
        let deadline = Instant::now() + timeout;
        loop {
            if self.seen.lock().last.is_some() {
                return Ok(());
            }
            if Instant::now() >= deadline {
                return Err(Error::node(
                    "simulator",
                    format!(
                        "missing: nothing on {} after {:.0} s. Start one (python3 clients/python/examples/reference_sim.py, \
                         a CARLA or CoppeliaSim adapter, slipstream-sim elsewhere) with the same -n/--namespace and a \
                         link to this machine (-e), or raise --sim-wait; `slipstream conform sim` checks it",
                        self.speed_key,
                        timeout.as_secs_f64()
                    ),
                ));
            }
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
    }

    /// Why the run is over, or None while it goes on: the simulator ended the scenario, ran
    /// `duration_s` of simulated time since it was first seen, or went silent.
    pub fn over(&self, duration_s: Option<f64>) -> Option<String> {
        let s = self.seen.lock();
        if let Some(reason) = &s.ended {
            return Some(format!("the simulator ended: {reason}"));
        }
        let ran_s = (s.newest_sim_ns - s.first_sim_ns.unwrap_or(s.newest_sim_ns)) as f64 / 1e9;
        if duration_s.is_some_and(|d| ran_s >= d) {
            return Some(format!("{ran_s:.1} s simulated"));
        }
        match s.last {
            Some(t) if t.elapsed() > SILENCE => {
                Some(format!("the simulator went silent ({} s without vehicle/speed)", SILENCE.as_secs()))
            }
            _ => None,
        }
    }
}
