//! The observer of `bench fleet`, run as its own process on the client PC's host
//! (`slipstream bench-fleet-watch`, hidden): one Zenoh session, one bus per vehicle namespace
//! (car0, car1, ...). Per vehicle it counts speed as the client PC receives it (losses from
//! the sequence numbers) and the loop's latency (frame published -> command applied, from the
//! stamps the messages carry, as `up` shows it). It subscribes to no frame: frames cross the
//! link for the detectors only. Prints one JSON report when stopped (SIGINT/SIGTERM).

use anyhow::Result;
use serde::{Deserialize, Serialize};

use slipstream_contract::bus::{Bus, CallbackSubscriber};
use slipstream_contract::config::ConnectArgs;
use slipstream_contract::topics;
use slipstream_observe::latency::{LatencyWatch, WHOLE_LOOP};

#[derive(Debug, Clone, clap::Args)]
pub struct FleetWatchArgs {
    /// The vehicles to watch, by number (car0, car3, ...)
    #[arg(long, value_delimiter = ',', required = true)]
    pub ids: Vec<usize>,
    /// Seconds to wait before counting (the loops start)
    #[arg(long, default_value_t = 3.0)]
    pub warmup: f64,
}

/// What the client PC saw of one vehicle.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct VehicleSeen {
    pub speed_received: u64,
    pub speed_lost: u64,
    pub loop_p50_ms: Option<f64>,
    pub loop_p99_ms: Option<f64>,
}

/// Watches until stopped; the report per vehicle.
pub async fn watch(connect: &ConnectArgs, args: FleetWatchArgs) -> Result<Vec<VehicleSeen>> {
    let session = zenoh::open(connect.zenoh_config()?).await.map_err(anyhow::Error::msg)?;
    let topics = connect.topic_map()?;
    let mut buses = Vec::new();
    for i in &args.ids {
        let map = topics.clone().with_namespace(&format!("car{i}"))?;
        buses.push(Bus::from_session(session.clone(), map, "fleet-watch").await?);
    }
    tokio::time::sleep(std::time::Duration::from_secs_f64(args.warmup)).await;
    let mut watched: Vec<(CallbackSubscriber, LatencyWatch)> = Vec::new();
    for bus in &buses {
        let speed = bus.subscribe_with(topics::VEHICLE_SPEED, |_| {}).await?;
        watched.push((speed, LatencyWatch::start(bus, true).await?));
    }
    slipstream_contract::process::stop_requested().await;
    let seen = watched
        .iter()
        .map(|(speed, latency)| {
            let s = speed.stats().snapshot();
            let whole = &latency.latency.lock().stats(false)[WHOLE_LOOP];
            VehicleSeen {
                speed_received: s.received,
                speed_lost: s.lost,
                loop_p50_ms: whole.p50_ms,
                loop_p99_ms: whole.p99_ms,
            }
        })
        .collect();
    drop(watched);
    drop(buses);
    session.close().await.map_err(anyhow::Error::msg)?;
    Ok(seen)
}
