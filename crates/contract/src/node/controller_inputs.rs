//! What a controller of the user's own reads besides the state it answers: the objects ahead,
//! the driver's settings (sim/ego, then acc/command), the camera's rate and the physics rate,
//! taken as they come and kept newest-first, so that an answer depends on its step's inputs
//! alone (docs/node-contract.md, "Lockstep from the controller's side").

use std::time::{Duration, Instant};

use super::law::{Ahead, DriverSettings};
use crate::bus::{Bus, BusError, StatsSnapshot, Subscriber};
use crate::msg::{self, AccCommand, CameraInfo, Detections, EgoInfo, GroundTruthObjects, SimClock};
use crate::topics;

/// The objects ahead, by the run's perception.
enum Objects {
    Camera(Subscriber<Detections>),
    GroundTruth(Subscriber<GroundTruthObjects>),
}

/// One objects message: its stamps and what is ahead, each gap still from the ego's origin.
struct Seen {
    stamp_ns: u64,
    pub_ns: u64,
    ahead: Vec<Ahead>,
}

impl Objects {
    fn seen_camera(r: crate::bus::Received<Detections>) -> Seen {
        let ahead = r.msg.detections.iter().map(|d| Ahead {
            id: d.track_id,
            gap_m: d.distance_m,
            lateral_m: d.lateral_offset_m,
            relative_speed_mps: d.relative_speed_mps,
            brake_lights: d.brake_lights,
        });
        Seen { stamp_ns: r.header.stamp_sim_ns, pub_ns: r.header.stamp_pub_ns, ahead: ahead.collect() }
    }

    fn seen_ground_truth(r: crate::bus::Received<GroundTruthObjects>) -> Seen {
        let ahead = r.msg.objects.iter().filter(|o| o.position_in_ego_m[0] > 0.0).map(|o| Ahead {
            id: o.id,
            gap_m: o.position_in_ego_m[0],
            lateral_m: o.position_in_ego_m[1],
            relative_speed_mps: o.velocity_in_ego_mps[0],
            brake_lights: o.brake_lights,
        });
        Seen { stamp_ns: r.header.stamp_sim_ns, pub_ns: r.header.stamp_pub_ns, ahead: ahead.collect() }
    }

    fn try_next(&self) -> Option<Seen> {
        match self {
            Objects::Camera(s) => s.try_recv().map(Self::seen_camera),
            Objects::GroundTruth(s) => s.try_recv().map(Self::seen_ground_truth),
        }
    }

    async fn next_within(&self, wait: Duration) -> Option<Seen> {
        match self {
            Objects::Camera(s) => s.recv_timeout(wait).await.map(Self::seen_camera),
            Objects::GroundTruth(s) => s.recv_timeout(wait).await.map(Self::seen_ground_truth),
        }
    }

    fn stats(&self) -> StatsSnapshot {
        match self {
            Objects::Camera(s) => s.stats().snapshot(),
            Objects::GroundTruth(s) => s.stats().snapshot(),
        }
    }
}

/// What the inputs said so far.
#[derive(Debug, Default)]
pub(super) struct Known {
    pub settings: DriverSettings,
    /// From the ego's origin (its rear axle) to its front bumper: sim/ego's.
    pub front_m: f64,
    pub camera_rate_hz: Option<f64>,
    pub physics_hz: Option<f64>,
    /// The newest objects, each gap from the ego's origin, their stamp and publish stamp.
    pub ahead: Vec<Ahead>,
    pub ahead_stamp_ns: Option<u64>,
    pub ahead_pub_ns: Option<u64>,
}

impl Known {
    /// Whether the state of `step` (stamped `t_ns`) came with a camera frame whose objects are
    /// still to come: by the clock rule once both rates are known, the first frame before.
    pub(super) fn frame_due(&self, step: u64, t_ns: u64) -> bool {
        if self.ahead_stamp_ns.is_some_and(|s| s >= t_ns) {
            return false;
        }
        match (self.camera_rate_hz, self.physics_hz) {
            (Some(rate), Some(physics)) => msg::due(step, rate, physics.round() as u32),
            _ => self.ahead_stamp_ns.is_none(),
        }
    }

    /// What is ahead, each gap from the ego's front bumper.
    pub(super) fn ahead_of_bumper(&self) -> Vec<Ahead> {
        self.ahead.iter().map(|a| Ahead { gap_m: a.gap_m - self.front_m, ..*a }).collect()
    }

    fn take_objects(&mut self, seen: Seen) {
        // Newest first: a late message of an older frame does not replace a newer one.
        if self.ahead_stamp_ns.is_none_or(|s| seen.stamp_ns >= s) {
            (self.ahead, self.ahead_stamp_ns, self.ahead_pub_ns) = (seen.ahead, Some(seen.stamp_ns), Some(seen.pub_ns));
        }
    }

    fn take_ego(&mut self, ego: EgoInfo) {
        self.front_m = ego.front_m();
        self.settings.set_speed_mps = ego.set_speed_mps;
        if let Some(gap) = ego.time_gap_s {
            self.settings.time_gap_s = gap;
        }
        self.settings.vehicle = Some(ego);
    }

    fn take_command(&mut self, c: &AccCommand) {
        let s = &mut self.settings;
        s.enabled = c.enable.unwrap_or(s.enabled);
        s.set_speed_mps = c.set_speed_mps.unwrap_or(s.set_speed_mps);
        s.time_gap_s = c.time_gap_s.unwrap_or(s.time_gap_s);
    }
}

/// The subscriptions besides vehicle/state.
pub(super) struct Inputs {
    objects: Objects,
    command: Subscriber<AccCommand>,
    clock: Subscriber<SimClock>,
    ego: Subscriber<EgoInfo>,
    info: Subscriber<CameraInfo>,
}

impl Inputs {
    pub(super) async fn open(bus: &Bus, ground_truth: bool) -> Result<Inputs, BusError> {
        let objects = match ground_truth {
            true => Objects::GroundTruth(bus.subscriber(topics::OBJECTS).await?),
            false => Objects::Camera(bus.subscriber(topics::PERCEPTION_OBJECTS).await?),
        };
        Ok(Inputs {
            objects,
            command: bus.subscriber(topics::ACC_COMMAND).await?,
            clock: bus.subscriber(topics::SIM_CLOCK).await?,
            ego: bus.subscriber(topics::SIM_EGO).await?,
            info: bus.subscriber(topics::CAMERA_FRONT_INFO).await?,
        })
    }

    /// Takes everything that arrived.
    pub(super) fn poll(&self, k: &mut Known) {
        while let Some(seen) = self.objects.try_next() {
            k.take_objects(seen);
        }
        while let Some(e) = self.ego.try_recv() {
            k.take_ego(e.msg);
        }
        while let Some(c) = self.command.try_recv() {
            k.take_command(&c.msg);
        }
        while let Some(c) = self.clock.try_recv() {
            k.physics_hz = Some(c.msg.physics_hz);
        }
        while let Some(i) = self.info.try_recv() {
            k.camera_rate_hz = Some(i.msg.rate_hz);
        }
    }

    /// Waits up to `wait` for the latched inputs an answer depends on: the vehicle (sim/ego)
    /// and the camera's rate. True when both are in.
    pub(super) async fn latched(&self, k: &mut Known, wait: Duration) -> bool {
        let deadline = Instant::now() + wait;
        loop {
            self.poll(k);
            if k.settings.vehicle.is_some() && k.camera_rate_hz.is_some() {
                return true;
            }
            if Instant::now() >= deadline {
                return false;
            }
            tokio::time::sleep(Duration::from_millis(5)).await;
        }
    }

    /// Waits up to `wait` for objects stamped `t_ns` or later. True when they came.
    pub(super) async fn objects_at(&self, k: &mut Known, t_ns: u64, wait: Duration) -> bool {
        let deadline = Instant::now() + wait;
        loop {
            self.poll(k);
            if k.ahead_stamp_ns.is_some_and(|s| s >= t_ns) {
                return true;
            }
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return false;
            }
            if let Some(seen) = self.objects.next_within(left).await {
                k.take_objects(seen);
            }
        }
    }

    pub(super) fn stats(&self) -> Vec<StatsSnapshot> {
        vec![self.objects.stats(), self.command.stats().snapshot(), self.ego.stats().snapshot()]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn seen(stamp_ns: u64, gap_m: f64) -> Seen {
        let ahead = vec![Ahead { id: 1, gap_m, lateral_m: 0.0, relative_speed_mps: 0.0, brake_lights: false }];
        Seen { stamp_ns, pub_ns: stamp_ns + 1, ahead }
    }

    #[test]
    fn a_late_message_of_an_older_frame_does_not_replace_a_newer_one() {
        let mut k = Known { front_m: 3.5, ..Known::default() };
        k.take_objects(seen(200, 40.0));
        k.take_objects(seen(100, 60.0));
        assert_eq!((k.ahead_stamp_ns, k.ahead_pub_ns), (Some(200), Some(201)));
        assert_eq!(k.ahead_of_bumper()[0].gap_m, 36.5, "the gap from the front bumper, not the rear axle");
    }

    #[test]
    fn a_frame_is_due_by_the_clock_rule_once_the_rates_are_known_and_the_first_before() {
        let mut k = Known::default();
        assert!(k.frame_due(0, 0), "nothing seen, rates unknown: the first frame is awaited");
        k.take_objects(seen(0, 40.0));
        assert!(!k.frame_due(1, 10_000_000), "rates unknown after the first frame: no wait");
        (k.camera_rate_hz, k.physics_hz) = (Some(20.0), Some(100.0));
        let due: Vec<u64> = (1..=10).filter(|&s| k.frame_due(s, s * 10_000_000)).collect();
        assert_eq!(due, [5, 10], "a 20 Hz camera on 100 Hz physics: every 5th step");
        k.take_objects(seen(50_000_000, 40.0));
        assert!(!k.frame_due(5, 50_000_000), "its objects are in");
    }

    #[test]
    fn a_command_changes_only_the_settings_it_names() {
        let mut k = Known::default();
        k.take_command(&AccCommand { enable: None, set_speed_mps: Some(22.0), time_gap_s: None });
        assert_eq!((k.settings.enabled, k.settings.set_speed_mps, k.settings.time_gap_s), (true, 22.0, 1.8));
        k.take_command(&AccCommand { enable: Some(false), set_speed_mps: None, time_gap_s: Some(2.5) });
        assert_eq!((k.settings.enabled, k.settings.set_speed_mps, k.settings.time_gap_s), (false, 22.0, 2.5));
    }
}
