//! How many controlled vehicles one simulator serves: the real-time factor of a fast-mode run
//! with N egos, each with its cameras, ground truth and vehicle topics published on a
//! loopback bus to a viewer that takes every ego's frames, at N = 1 and more. Fast mode runs as
//! fast as the machine allows, so its real-time factor is the headroom: N x factor is how many
//! such egos the simulator would serve at real time if the cost grows with N alone. Beside it
//! the same with the cameras shrunk to 80x60 and the narrow one off, a stand-in for egos driven
//! on ground truth (the simulator publishes ground truth with each frame, so a frame stays):
//! what remains is physics, ground truth and the bus.

use std::time::Duration;

use anyhow::{Context, Result};

use super::peer::loopback_config;
use slipstream_contract::topics;
use slipstream_sim::settings::{Mode, SimSettings};
use slipstream_sim::{Scenario, World};

/// Lanes the egos are spread over, and the spacing along a lane.
const LANES: usize = 3;
const SPACING_M: f64 = 60.0;

/// A scenario with `n` egos, three lanes abreast, 60 m apart along each lane, cruising.
pub(crate) fn scenario(n: usize, duration_s: f64) -> Result<Scenario> {
    let egos: Vec<String> = (0..n)
        .map(|k| {
            let s = 2000.0 - SPACING_M * (k / LANES) as f64;
            format!("{{ namespace: 'car{}', lane: {}, s_m: {s}, speed_mps: 25 }}", k + 1, k % LANES)
        })
        .collect();
    let text = format!(
        "{{ name: 'bench-egos-{n}', duration_s: {duration_s}, road: {{ lanes: {LANES}, length_m: 50000 }}, egos: [{}] }}",
        egos.join(", ")
    );
    Scenario::parse(&text, "bench egos").map_err(anyhow::Error::msg)
}

/// The settings of an ego driven on ground truth, as far as this simulator has them: the front
/// camera 80x60, the narrow one off.
pub(crate) fn ground_truth_settings() -> SimSettings {
    let mut s = SimSettings { mode: Mode::Fast, ..SimSettings::default() };
    s.camera.width = 80;
    s.camera.height = 60;
    s.narrow_camera.enabled = false;
    s
}

/// The real-time factor of a fast run of `n` egos under `settings`, every ego's front frames
/// taken by a viewer in another session on loopback.
pub(crate) async fn fast_rtf(n: usize, settings: &SimSettings, sim_s: f64) -> Result<f64> {
    fast_rtf_of(scenario(n, sim_s)?, settings).await
}

/// The real-time factor of a fast run of `scenario` under `settings`, every ego's front frames
/// taken by a viewer in another session on loopback (through shared memory, so publishing is
/// included).
pub(crate) async fn fast_rtf_of(scenario: Scenario, settings: &SimSettings) -> Result<f64> {
    let n = scenario.egos().len();
    let sim_session = zenoh::open(loopback_config(Some("tcp/127.0.0.1:0"), &[])?).await.map_err(anyhow::Error::msg)?;
    let ep = sim_session.info().locators().await.first().context("sim session has no locator")?.to_string();
    let viewer = zenoh::open(loopback_config(None, std::slice::from_ref(&ep))?).await.map_err(anyhow::Error::msg)?;
    let map = slipstream_contract::TopicMap::default().with_namespace(&format!("bench-egos-{}", std::process::id()))?;
    let sim_bus = slipstream_contract::Bus::from_session(sim_session, map.clone(), "bench-sim").await?;
    let view_bus = slipstream_contract::Bus::from_session(viewer, map, "bench-viewer").await?;
    let mut frames = Vec::new();
    for ego in scenario.egos() {
        let ns = ego.namespace.as_deref().unwrap_or_default();
        frames.push(view_bus.scoped(ns)?.frame_subscriber(topics::CAMERA_FRONT).await?);
        // A short fast run is over in milliseconds: it starts once the simulator's session
        // knows the viewer takes this ego's frames.
        let probe = sim_bus.scoped(ns)?.publisher(topics::CAMERA_FRONT).await?;
        anyhow::ensure!(probe.wait_for_subscriber(Duration::from_secs(10)).await, "the viewer never matched {ns}");
    }
    let settings = SimSettings { mode: Mode::Fast, ..settings.clone() };
    let world = World::new(scenario, 1, settings.physics_hz);
    let report = slipstream_sim::run(&sim_bus, world, &settings, std::future::pending()).await?;
    // Every ego's frames were matched above, so each was published; the viewer reads them
    // drop-when-congested, and on a busy machine a short fast run can lose all of one ego's:
    // said, not failed (the figure is the simulator's rate with its frames published).
    let starved = frames.iter().filter(|f| f.stats().snapshot().received == 0).count();
    if starved > 0 {
        tracing::warn!("{starved} of {n} egos' frames never reached the viewer (dropped on the way: a busy machine)");
    }
    sim_bus.close().await?;
    view_bus.close().await?;
    Ok(report.real_time_factor)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_egos_are_spread_over_the_lanes_and_apart() {
        let s = scenario(7, 5.0).unwrap();
        assert_eq!(s.egos().len(), 7);
        assert_eq!((s.egos()[4].lane, s.egos()[4].s_m), (1, 2000.0 - SPACING_M));
        assert!(ground_truth_settings().check().is_ok());
    }
}
