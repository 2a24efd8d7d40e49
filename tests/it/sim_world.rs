//! The simulator's world without the bus: vehicle physics, collisions, traffic, determinism
//! of the core. Bands are stated here and in docs/simulator.md.

use slipstream::msg::ControlCommand;
use slipstream::sim::world::{EgoInput, World, EGO_ID};
use slipstream::sim::Scenario;

const HZ: u32 = 100;

fn world(text: &str) -> World {
    let s = Scenario::parse(text, "test").unwrap_or_else(|e| panic!("{e}"));
    let seed = s.seed;
    World::new(s, seed, HZ)
}

fn empty_road(speed_mps: f64) -> World {
    world(&format!(
        "{{ name: 'empty', duration_s: 600, road: {{ length_m: 20000 }}, ego: {{ lane: 1, speed_mps: {speed_mps} }} }}"
    ))
}

fn command(throttle: f32, brake: f32) -> EgoInput {
    EgoInput::Command(ControlCommand { throttle, brake, ..ControlCommand::NEUTRAL })
}

#[test]
fn full_throttle_reaches_100_kmh_in_a_plausible_time_and_tops_out_plausibly() {
    let mut w = empty_road(0.0);
    let mut t_100 = None;
    for step in 0..(150 * HZ) {
        w.step(command(1.0, 0.0));
        if t_100.is_none() && w.ego().forward_speed_mps() >= 100.0 / 3.6 {
            t_100 = Some(step as f64 / HZ as f64);
        }
    }
    let t_100 = t_100.expect("reaches 100 km/h");
    assert!((6.0..=12.0).contains(&t_100), "0-100 km/h in {t_100:.1} s (band 6-12 s)");
    let top_kmh = w.ego().forward_speed_mps() * 3.6;
    println!("0-100 km/h: {t_100:.2} s, speed after 150 s: {top_kmh:.1} km/h");
    assert!((180.0..=250.0).contains(&top_kmh), "top speed {top_kmh:.0} km/h (band 180-250)");
    assert!(w.ego().lane == 1, "lane keeping holds the lane at full speed");
}

#[test]
fn full_brake_decelerates_at_8_to_10_mps2_and_stops_without_rolling_back() {
    let mut w = empty_road(100.0 / 3.6);
    w.step(command(0.0, 1.0));
    let v0 = w.ego().forward_speed_mps();
    for _ in 0..HZ {
        w.step(command(0.0, 1.0));
    }
    // The brake builds up through the actuator lag (0.3 s): over the first second it gives
    // about 70% of its full deceleration, over the second all of it.
    let first = v0 - w.ego().forward_speed_mps();
    let v1 = w.ego().forward_speed_mps();
    for _ in 0..HZ {
        w.step(command(0.0, 1.0));
    }
    let decel = v1 - w.ego().forward_speed_mps();
    println!("full brake from 100 km/h: {first:.2} m/s2 over the first second, {decel:.2} over the second");
    assert!((5.5..=7.5).contains(&first), "first second, brake still building: {first:.2} m/s2");
    assert!((8.0..=10.0).contains(&decel), "full brake: {decel:.2} m/s2 (band 8-10)");
    for _ in 0..(4 * HZ) {
        w.step(command(0.0, 1.0));
    }
    let v = w.ego().forward_speed_mps();
    assert!(v.abs() < 0.01, "stands still: {v}");
    let state = w.ego_state();
    assert_eq!(state.applied.brake, 1.0);
}

#[test]
fn coasting_slows_down_gently() {
    let mut w = empty_road(100.0 / 3.6);
    let v0 = w.ego().forward_speed_mps();
    for _ in 0..(10 * HZ) {
        w.step(command(0.0, 0.0));
    }
    let decel = (v0 - w.ego().forward_speed_mps()) / 10.0;
    println!("coasting from 100 km/h: {decel:.2} m/s2 over 10 s");
    assert!((0.2..=1.0).contains(&decel), "coasting from 100 km/h: {decel:.2} m/s2 (band 0.2-1.0)");
}

#[test]
fn driving_into_a_stopped_car_is_a_collision_that_ends_the_scenario() {
    let mut w = world(
        "{ name: 'crash', duration_s: 30, variation: { gap_m: 0, speed_mps: 0 }, ego: { lane: 1, speed_mps: 15 }, traffic: [ { lane: 1, gap_m: 30, speed_mps: 0 } ] }",
    );
    let mut collisions = Vec::new();
    let mut ended = None;
    for _ in 0..(10 * HZ) {
        let events = w.step(EgoInput::Cruise);
        collisions.extend(events.collisions);
        if let Some(end) = events.ended {
            ended = Some(end);
            break;
        }
    }
    let c = collisions.first().expect("a collision");
    assert!(c.involves_ego() && (c.id_a == 1 || c.id_b == 1) && (c.id_a == EGO_ID || c.id_b == EGO_ID));
    assert!((12.0..=16.0).contains(&c.relative_speed_mps), "impact at {:.1} m/s", c.relative_speed_mps);
    let end = ended.expect("the collision ends the scenario");
    assert!(!end.success && end.reason.contains("collided with vehicle 1"), "{end:?}");
    assert_eq!(w.ego_collisions(), 1);
}

#[test]
fn the_lead_brakes_at_the_scripted_rate() {
    let mut w = world(
        "{ name: 'l', duration_s: 40, variation: { gap_m: 0, speed_mps: 0 }, ego: { lane: 1, speed_mps: 0 }, traffic: [ { lane: 1, gap_m: 45, speed_mps: 25, actions: [ { at_s: 2, speed_mps: 0, accel_mps2: 6 } ] } ] }",
    );
    let lead_speed = |w: &World| w.vehicles()[1].forward_speed_mps();
    for _ in 0..(3 * HZ) {
        w.step(command(0.0, 1.0));
    }
    let v0 = lead_speed(&w);
    for _ in 0..HZ {
        w.step(command(0.0, 1.0));
    }
    let decel = v0 - lead_speed(&w);
    assert!((5.5..=6.5).contains(&decel), "lead decelerates at {decel:.2} m/s2");
    for _ in 0..(5 * HZ) {
        w.step(command(0.0, 1.0));
    }
    assert!(lead_speed(&w).abs() < 0.05, "lead stopped");
}

#[test]
fn the_ego_keeps_its_lane_through_curves_and_traffic_changes_lanes_when_told() {
    let mut w = world(&std::fs::read_to_string("scenarios/curve-follow.json5").unwrap());
    let mut worst = 0.0f64;
    for _ in 0..(60 * HZ) {
        w.step(EgoInput::Cruise);
        worst = worst.max((w.ego().d_m - w.road().lane_center_d(1)).abs());
    }
    assert!(worst < 0.5, "ego strays {worst:.2} m from its lane centre");

    let mut w = world(&std::fs::read_to_string("scenarios/cut-in.json5").unwrap());
    assert_eq!(w.vehicles()[2].lane, 2);
    for _ in 0..(12 * HZ) {
        w.step(EgoInput::Cruise);
    }
    let cutter = w.vehicles()[2];
    assert_eq!(cutter.lane, 1, "the cutter is in the ego's lane after its lane change");
    assert!((cutter.d_m - w.road().lane_center_d(1)).abs() < 0.4);
}

#[test]
fn same_seed_same_world_other_seed_other_start() {
    let run = |seed: u64| {
        let s = Scenario::find("busy-traffic").unwrap();
        let mut w = World::new(s, seed, HZ);
        for _ in 0..(5 * HZ) {
            w.step(EgoInput::Cruise);
        }
        w.vehicles().iter().map(|v| (v.rear_axle.x.to_bits(), v.rear_axle.y.to_bits(), v.color)).collect::<Vec<_>>()
    };
    assert_eq!(run(7), run(7));
    assert_ne!(run(7), run(8));
}

/// A step in the command reaches the wheels through a first-order lag: 63% of the step after
/// the vehicle's actuator_lag_s (0.3 s for the car), nearly all after five times that.
#[test]
fn throttle_and_brake_act_through_the_actuator_lag() {
    let lag = slipstream::vehicle::VehicleParams::CAR.actuator_lag_s;
    let mut w = empty_road(25.0);
    let brake_for = |w: &mut World, steps: u32| {
        for _ in 0..steps {
            w.step(command(0.0, 0.5));
        }
    };
    let steps = (lag * HZ as f64).round() as u32;
    brake_for(&mut w, steps);
    let applied_at_lag = w.ego_actuation().1;
    brake_for(&mut w, 4 * steps);
    let applied_later = w.ego_actuation().1;
    assert!((0.5 * 0.6..=0.5 * 0.67).contains(&applied_at_lag), "brake applied after the lag: {applied_at_lag}");
    assert!(applied_later > 0.49, "brake applied after five lags: {applied_later}");
}

/// A lane change takes its duration_s: the lateral move is done (within 10% of a lane) by then,
/// and under way most of that time, not finished early by a jerk of the wheel.
#[test]
fn a_lane_change_takes_its_duration() {
    for (speed, duration) in [(25.0, 4.0), (12.0, 3.0), (30.0, 6.0)] {
        let mut w = world(&format!(
            "{{ name: 'lc', duration_s: 60, variation: {{ gap_m: 0, speed_mps: 0 }}, ego: {{ lane: 1, speed_mps: {speed} }}, traffic: [ {{ lane: 1, gap_m: 60, speed_mps: {speed}, actions: [ {{ at_s: 1, lane: 2, duration_s: {duration} }} ] }} ] }}"
        ));
        let (from, to) = (w.road().lane_center_d(1), w.road().lane_center_d(2));
        let (mut t_half, mut t_done) = (None, None);
        for step in 0..(20 * HZ) {
            w.step(EgoInput::Cruise);
            let t = (step + 1) as f64 / HZ as f64 - 1.0;
            let moved = (w.vehicles()[1].d_m - from) / (to - from);
            if t_half.is_none() && moved >= 0.5 {
                t_half = Some(t);
            }
            if t_done.is_none() && moved >= 0.9 {
                t_done = Some(t);
            }
        }
        let (half, done) = (t_half.expect("moves over"), t_done.expect("arrives"));
        println!("{speed} m/s, duration {duration} s: half-way at {half:.2} s, 90% at {done:.2} s");
        assert!((0.35 * duration..=0.65 * duration).contains(&half), "half-way at {half:.2} s of {duration}");
        assert!(done <= 1.1 * duration, "90% of the way at {done:.2} s of {duration}");
    }
}

/// A vehicle placed across its lane (`offset_m`) starts and stays there, off the road on the
/// shoulder too (ground truth then puts it in no lane), and an action moves it to a new offset.
#[test]
fn a_vehicle_holds_its_place_across_the_lane_and_moves_when_told() {
    let mut w = world(
        "{ name: 'off', duration_s: 60, variation: { gap_m: 0, speed_mps: 0 }, ego: { lane: 1, speed_mps: 20 }, \
         traffic: [ { lane: 0, offset_m: -3.0, gap_m: 80, speed_mps: 0 }, \
                    { lane: 2, offset_m: 1.0, gap_m: 40, speed_mps: 20, actions: [ { at_s: 5, offset_m: -1.0, duration_s: 2 } ] } ] }",
    );
    let (shoulder, mover) = (w.road().lane_center_d(0) - 3.0, w.road().lane_center_d(2));
    let (mut worst_shoulder, mut worst_before) = (0.0f64, 0.0f64);
    for step in 0..(10 * HZ) {
        w.step(EgoInput::Cruise);
        worst_shoulder = worst_shoulder.max((w.vehicles()[1].d_m - shoulder).abs());
        if step < 5 * HZ {
            worst_before = worst_before.max((w.vehicles()[2].d_m - (mover + 1.0)).abs());
        }
    }
    assert!(worst_shoulder < 0.05, "the parked car moved {worst_shoulder:.2} m across");
    assert_eq!(w.vehicles()[1].lane, -1, "on the shoulder it is in no lane");
    assert!(worst_before < 0.3, "strays {worst_before:.2} m from its offset");
    let after = w.vehicles()[2].d_m - mover;
    assert!((after + 1.0).abs() < 0.3, "at {after:.2} m from the lane centre after moving to -1 m");
    assert_eq!(w.vehicles()[2].lane, 2, "a metre either side of the centre is still its lane");
}

/// Random lane changes accept a gap only when nobody has to brake hard for it (the new
/// follower in the target lane and the changer behind its new leader, MOBIL's safety
/// criterion): dense traffic that weaves all the time has no crash of its own.
#[test]
fn weaving_traffic_accepts_only_safe_gaps() {
    for seed in [3, 7, 11] {
        let mut w = world(&format!(
            "{{ name: 'weave', duration_s: 90, seed: {seed}, road: {{ lanes: 4 }}, ego: {{ lane: 0, speed_mps: 20 }}, random_traffic: {{ count: 60, range_m: [-200, 600], min_spacing_m: 20, speed_mps: [15, 33], lane_change_every_s: 5, van_share: 0.2, truck_share: 0.1 }} }}"
        ));
        for _ in 0..(90 * HZ) {
            w.step(EgoInput::Follow);
        }
        assert_eq!(w.traffic_collisions(), 0, "seed {seed}: traffic crashed into traffic");
    }
}

/// A lane that ends: traffic in it moves over before the taper when the gap beside is safe;
/// when it is not (a column beside it), it stops in the taper and goes once there is room; a
/// vehicle standing in it stays. The road's edge moves in over the taper.
#[test]
fn traffic_in_a_lane_that_ends_merges_before_its_end_or_waits() {
    let mut w = world(
        "{ name: 'merge', duration_s: 120, seed: 2, road: { lane_ends: [ { lane: 0, end_m: 600, taper_m: 150 } ] },
           ego: { lane: 2, speed_mps: 0 },
           traffic: [
             { lane: 0, gap_m: 400, speed_mps: 10 },
             { lane: 0, gap_m: 500, speed_mps: 0 },
             // A column beside it at its speed, too tight to enter: no safe gap until it has passed.
             { lane: 1, gap_m: 340, speed_mps: 10 }, { lane: 1, gap_m: 352, speed_mps: 10 }, { lane: 1, gap_m: 364, speed_mps: 10 },
             { lane: 1, gap_m: 376, speed_mps: 10 }, { lane: 1, gap_m: 388, speed_mps: 10 }, { lane: 1, gap_m: 400, speed_mps: 10 },
             { lane: 1, gap_m: 412, speed_mps: 10 }, { lane: 1, gap_m: 424, speed_mps: 10 },
           ] }",
    );
    let (mut max_s_in_lane_0, mut waited) = (0.0f64, false);
    for _ in 0..(60 * HZ) {
        let events = w.step(EgoInput::Cruise);
        assert!(events.collisions.is_empty(), "{:?}", events.collisions);
        let v = w.vehicles()[1];
        if v.lane == 0 {
            max_s_in_lane_0 = max_s_in_lane_0.max(v.s_front_m());
            waited |= v.forward_speed_mps() < 0.5;
        }
    }
    let (merger, standing) = (w.vehicles()[1], w.vehicles()[2]);
    assert_eq!(merger.lane, 1, "it moved over: {merger:?}");
    // It aims to stop at the taper's middle (525 m); the traffic's linear following law
    // overshoots a few metres: within the taper's first two thirds.
    assert!(max_s_in_lane_0 < 600.0 - 50.0, "in the ending lane up to {max_s_in_lane_0:.1} m");
    assert!(waited, "the column beside left no gap: it waited at the end");
    assert_eq!(standing.lane, 0, "a standing vehicle stays");
    let road = w.road();
    assert_eq!(road.edges_d(300.0), (-5.25, 5.25));
    assert!((road.edges_d(525.0).0 - (-5.25 + 1.75)).abs() < 1e-9);
    assert_eq!(road.edges_d(700.0).0, -1.75);
}
