//! Several controlled vehicles in one world: each driven by its own commands, each ego's topics
//! in its namespace, lockstep waiting for every ego's controller, a late one named with its
//! namespace, and collisions between two egos counted as such.

use std::sync::Arc;
use std::time::Duration;

use parking_lot::Mutex;
use slipstream::msg::{self, ControlCommand, GroundTruthObjects, SimEvent, SimEventKind, VehicleState};
use slipstream::sim::settings::{Mode, OnTimeout, SimSettings};
use slipstream::sim::world::{EgoInput, World};
use slipstream::sim::Scenario;
use slipstream::{Bus, TopicMap};

use crate::common::{connected_session, listening_session};

/// Two cars in lane 1, car2 30 m behind car1, nothing else on the road.
fn two_egos(duration_s: f64) -> Scenario {
    Scenario::parse(
        &format!(
            "{{ name: 'two', duration_s: {duration_s}, road: {{ length_m: 5000 }}, egos: [
                {{ namespace: 'car1', lane: 1, s_m: 120, speed_mps: 20 }},
                {{ namespace: 'car2', lane: 1, s_m: 90, speed_mps: 20 }} ] }}"
        ),
        "test",
    )
    .unwrap_or_else(|e| panic!("{e}"))
}

fn command(throttle: f32, brake: f32) -> EgoInput {
    EgoInput::Command(ControlCommand { throttle, brake, ..ControlCommand::NEUTRAL })
}

#[test]
fn each_ego_follows_its_own_commands_and_a_collision_between_two_is_counted_once_as_such() {
    let mut w = World::new(two_egos(60.0), 1, 100);
    assert_eq!((w.ego_count(), w.ego_at(1).id), (2, 1));
    for _ in 0..200 {
        w.step_all(&[command(0.0, 0.4), command(0.3, 0.0)]);
    }
    let (lead, follower) = (w.ego_state_of(0), w.ego_state_of(1));
    assert!(lead.speed_mps < 15.0 && follower.speed_mps > 20.0, "{} {}", lead.speed_mps, follower.speed_mps);
    assert_eq!((lead.applied.brake, follower.applied.throttle), (0.4, 0.3));
    let mut ended = None;
    for _ in 0..2000 {
        if let Some(end) = w.step_all(&[command(0.0, 1.0), command(1.0, 0.0)]).ended {
            ended = Some(end);
            break;
        }
    }
    let end = ended.expect("car2 ran into car1");
    assert!(!end.success && end.reason.contains("collided with vehicle"), "{end:?}");
    assert_eq!((w.collisions_of(0), w.collisions_of(1), w.collisions_between_egos()), (1, 1, 1));
    assert_eq!(w.traffic_collisions(), 0);
}

/// Every ego's lockstep run of these tests: sim_node's settings (100 Hz, small frames).
fn settings(wait_for: &[&str]) -> SimSettings {
    crate::sim_node::settings(Mode::Lockstep, wait_for)
}

/// A controller in one ego's namespace: answers each vehicle/state before `until_step` with
/// `throttle` and `brake`.
async fn controller(bus: Bus, throttle: f32, brake: f32, until_step: u64) -> tokio::task::JoinHandle<()> {
    crate::sim_node::answering(bus, until_step, move |_| ControlCommand { throttle, brake, ..ControlCommand::NEUTRAL })
        .await
}

/// Every sample under the namespaces, by key.
type Seen = Arc<Mutex<Vec<(String, Vec<u8>)>>>;

async fn watch_all(session: &zenoh::Session) -> (Seen, zenoh::pubsub::Subscriber<()>) {
    let seen: Seen = Arc::default();
    let s = seen.clone();
    let sub = session
        .declare_subscriber("**")
        .callback(move |x: zenoh::sample::Sample| {
            s.lock().push((x.key_expr().to_string(), x.payload().to_bytes().into_owned()))
        })
        .await
        .unwrap();
    (seen, sub)
}

fn decoded<M: serde::de::DeserializeOwned + msg::Message>(seen: &Seen, key: &str) -> Vec<M> {
    seen.lock().iter().filter(|(k, _)| k == key).map(|(_, b)| msg::decode::<M>(b).unwrap().msg).collect()
}

/// The simulator's bus, a recorder of every key, and a controller in each of car1 and car2:
/// car1's brakes at 0.3 every step, car2's gives 0.2 throttle until `car2_until_step`.
struct TwoLoops {
    sim: Bus,
    seen: Seen,
    /// The recorder's session and subscription: alive as long as the run.
    _recorder: (zenoh::Session, zenoh::pubsub::Subscriber<()>),
    controllers: [tokio::task::JoinHandle<()>; 2],
}

impl TwoLoops {
    async fn start(car2_until_step: u64) -> TwoLoops {
        let map = TopicMap::default();
        let (s_sim, ep) = listening_session().await;
        let (s1, s2, s_rec) =
            (connected_session(&ep).await, connected_session(&ep).await, connected_session(&ep).await);
        let (seen, _sub) = watch_all(&s_rec).await;
        let in_ns = |ns: &str| map.clone().with_namespace(ns).unwrap();
        let c1 = controller(Bus::from_session(s1, in_ns("car1"), "ctl").await.unwrap(), 0.0, 0.3, u64::MAX).await;
        let c2 =
            controller(Bus::from_session(s2, in_ns("car2"), "ctl").await.unwrap(), 0.2, 0.0, car2_until_step).await;
        let sim = Bus::from_session(s_sim, map, "sim").await.unwrap();
        TwoLoops { sim, seen, _recorder: (s_rec, _sub), controllers: [c1, c2] }
    }

    /// Lets the last messages land and stops the controllers.
    async fn settle(&self) {
        tokio::time::sleep(Duration::from_millis(300)).await;
        self.controllers.iter().for_each(|c| c.abort());
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn every_ego_publishes_in_its_namespace_and_lockstep_waits_for_each_ones_controller() {
    let run = TwoLoops::start(u64::MAX).await;
    let world = World::new(two_egos(2.0), 1, 100);
    let report = within!(slipstream::sim::run(&run.sim, world, &settings(&["ctl"]), std::future::pending())).unwrap();
    assert_eq!((report.steps, report.lockstep_timeouts), (200, 0), "{report:?}");
    let namespaces: Vec<&str> = report.egos.iter().map(|e| e.namespace.as_str()).collect();
    assert_eq!(namespaces, ["car1", "car2"]);
    run.settle().await;
    let seen = &run.seen;
    let (car1, car2) =
        (decoded::<VehicleState>(seen, "car1/vehicle/state"), decoded::<VehicleState>(seen, "car2/vehicle/state"));
    assert!(car1.len() >= 199 && car2.len() >= 199, "{} {}", car1.len(), car2.len());
    // Each ego applied its own controller's answer to the step before.
    assert!(car1.iter().skip(1).all(|s| s.applied.brake == 0.3 && s.applied.answers_step == Some(s.step - 1)));
    assert!(car2.iter().skip(1).all(|s| s.applied.throttle == 0.2 && s.applied.answers_step == Some(s.step - 1)));
    assert!(car1.last().unwrap().speed_mps < car2.last().unwrap().speed_mps);
    assert!(decoded::<VehicleState>(seen, "vehicle/state").is_empty(), "nothing in the run's own namespace");
    // Each ego's ground truth has the other: car1 ahead of car2, car2 behind car1.
    let truth = |key| decoded::<GroundTruthObjects>(seen, key).pop().expect(key);
    let ahead = truth("car2/objects").objects.into_iter().find(|o| o.id == 0).expect("car1 in car2's truth");
    let behind = truth("car1/objects").objects.into_iter().find(|o| o.id == 1).expect("car2 in car1's truth");
    assert!(ahead.position_in_ego_m[0] > 20.0 && behind.position_in_ego_m[0] < -20.0);
    for ns in ["car1", "car2"] {
        let key = format!("{ns}/camera/front");
        assert!(seen.lock().iter().any(|(k, _)| *k == key), "{key}");
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn a_late_ego_controller_is_named_with_its_namespace_and_the_others_answers_still_count() {
    let run = TwoLoops::start(50).await;
    let mut s = settings(&["ctl"]);
    s.lockstep.step_timeout_ms = 300;
    s.lockstep.on_timeout = OnTimeout::Stop;
    let world = World::new(two_egos(5.0), 1, 100);
    let report = within!(slipstream::sim::run(&run.sim, world, &s, std::future::pending())).unwrap();
    assert_eq!(report.steps, 50, "{report:?}");
    let end = report.end.expect("ended");
    assert!(end.reason.contains("lockstep timeout at step 50 waiting for car2/ctl"), "{end:?}");
    assert_eq!(report.egos.iter().map(|e| e.lockstep_timeouts).collect::<Vec<_>>(), [0, 1]);
    run.settle().await;
    let late_in = |key| {
        decoded::<SimEvent>(&run.seen, key)
            .into_iter()
            .filter_map(|e| match e.kind {
                SimEventKind::ControlTimeout { late } => Some(late),
                _ => None,
            })
            .collect::<Vec<_>>()
    };
    assert_eq!(late_in("car2/sim/events"), [vec!["ctl".to_string()]]);
    assert!(late_in("car1/sim/events").is_empty());
}
