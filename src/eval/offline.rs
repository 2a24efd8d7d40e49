//! The closed loop in one process, without the bus: the world, ground truth as perception at
//! the camera rate, the controller at every step. Deterministic and fast; the tests tune and
//! check the control law with it. `slipstream eval acc` runs the real processes instead.

use super::trace::{truth_lead, Sample, Trace};
use crate::acc::{AccSettings, Controller, EgoNow, PerceptionFrame};
use crate::msg::{due, ControlCommand};
use crate::sim::ground_truth::ground_truth;
use crate::sim::world::{EgoInput, World};
use crate::sim::Scenario;

/// Runs `scenario` to its end with the ACC on ground truth; physics at `physics_hz`,
/// perception at `camera_hz`.
pub fn run(scenario: Scenario, settings: AccSettings, physics_hz: u32, camera_hz: f64) -> Trace {
    let seed = scenario.seed;
    let standstill_m = settings.standstill_m;
    let mut world = World::new(scenario, seed, physics_hz);
    let mut ctl = Controller::new(settings);
    let mut trace = Trace { standstill_m, samples: Vec::new(), collisions: 0, end: String::new() };
    let mut truth = None;
    loop {
        let k = world.step_count();
        let t_s = world.time_ns() as f64 / 1e9;
        let state = world.ego_state();
        let ego = EgoNow {
            t_s,
            speed_mps: world.measured_speed_mps(),
            accel_mps2: state.acceleration_in_body_mps2[0],
            yaw_rate_radps: state.yaw_rate_radps,
        };
        if due(k, camera_hz, physics_hz) {
            let gt = ground_truth(&world, &[]);
            truth = truth_lead(&gt, state.lane, ctl.settings().vehicle.front_overhang_from_origin_m);
            ctl.perceive(&PerceptionFrame::from_ground_truth(t_s, &gt), &ego);
        }
        let out = ctl.step(&ego, &[]);
        trace.samples.push(Sample::new(t_s, &state, &out.status, truth));
        let cmd = ControlCommand {
            throttle: out.throttle,
            brake: out.brake,
            steer: 0.0,
            answers_step: Some(k),
            perception_stamp_pub_ns: None,
        };
        let events = world.step(EgoInput::Command(cmd));
        trace.collisions += events.collisions.iter().filter(|c| c.involves_ego()).count() as u64;
        if let Some(end) = events.ended {
            trace.end = end.reason;
            return trace;
        }
    }
}

#[cfg(test)]
mod tests {
    use crate::acc::{AccSettings, PerceptionSource};
    use crate::eval::Metrics;
    use crate::sim::scenario::{Scenario, BUILT_IN};

    #[test]
    fn every_built_in_scenario_passes_on_ground_truth_in_one_process() {
        for (name, _) in BUILT_IN {
            let scenario = Scenario::find(name).unwrap();
            let settings = AccSettings {
                perception: PerceptionSource::GroundTruth,
                set_speed_mps: scenario.ego.set_speed_mps.unwrap_or(scenario.ego.speed_mps),
                ..AccSettings::default()
            };
            let trace = super::run(scenario, settings, 100, 20.0);
            let m = Metrics::of(&trace);
            let failed: Vec<_> = m.checks.iter().filter(|c| !c.pass).collect();
            assert!(m.pass, "{name}: {failed:?}");
            assert!(trace.samples.len() > 1000, "{name}: {} samples", trace.samples.len());
        }
    }
}
