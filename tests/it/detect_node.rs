//! slipstream-detect end to end over Zenoh: the simulator publishes frames, the detector node
//! publishes perception/objects, and a third node matches them to ground truth by simulation
//! time.

use std::sync::Arc;
use std::time::Duration;

use parking_lot::Mutex;
use slipstream::msg::{self, Detections, GroundTruthObjects};
use slipstream::perception::DetectSettings;
use slipstream::sim::settings::{Mode, SimSettings};
use slipstream::sim::{Scenario, World};
use slipstream::{topics, Bus, TopicMap};

async fn session(listen: bool, connect: &[&str]) -> (zenoh::Session, Option<String>) {
    let mut c = zenoh::Config::default();
    c.insert_json5("mode", "\"peer\"").unwrap();
    c.insert_json5("scouting/multicast/enabled", "false").unwrap();
    c.insert_json5("listen/endpoints", if listen { r#"["tcp/127.0.0.1:0"]"# } else { "[]" }).unwrap();
    c.insert_json5("connect/endpoints", &serde_json::to_string(connect).unwrap()).unwrap();
    let s = zenoh::open(c).await.unwrap();
    let ep = if listen { Some(s.info().locators().await.first().unwrap().to_string()) } else { None };
    (s, ep)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn the_detector_node_reports_the_lead_matched_to_ground_truth_by_time() {
    let (s_sim, sim_ep) = session(true, &[]).await;
    let sim_ep = sim_ep.unwrap();
    let (s_det, det_ep) = session(true, &[&sim_ep]).await;
    let det_ep = det_ep.unwrap();
    let (s_watch, _) = session(false, &[&sim_ep, &det_ep]).await;
    let map = TopicMap::default();

    type Seen<T> = Arc<Mutex<Vec<(u64, T)>>>;
    let detections: Seen<Detections> = Arc::default();
    let truth: Seen<GroundTruthObjects> = Arc::default();
    let watcher = Bus::from_session(s_watch, map.clone(), "watcher").await.unwrap();
    let _d = {
        let seen = detections.clone();
        watcher
            .subscribe_with(topics::PERCEPTION_OBJECTS, move |r| seen.lock().push((r.header.stamp_sim_ns, r.msg)))
            .await
            .unwrap()
    };
    let _t = {
        let seen = truth.clone();
        watcher
            .subscribe_with(topics::OBJECTS, move |r| seen.lock().push((r.header.stamp_sim_ns, r.msg)))
            .await
            .unwrap()
    };

    let det_bus = Bus::from_session(s_det, map.clone(), "detect").await.unwrap();
    let (stop_tx, stop_rx) = tokio::sync::oneshot::channel::<()>();
    let detector = tokio::spawn(async move {
        let stats = slipstream::perception::node::run(&det_bus, DetectSettings::default(), async {
            let _ = stop_rx.await;
        })
        .await;
        (stats, det_bus)
    });
    tokio::time::sleep(Duration::from_millis(500)).await;

    let sim = Bus::from_session(s_sim, map, "sim").await.unwrap();
    let mut scenario = Scenario::find("steady-follow").unwrap();
    scenario.duration_s = 3.0;
    let settings = SimSettings { mode: Mode::Realtime, ..SimSettings::default() };
    within!(slipstream::sim::run(
        &sim,
        World::new(scenario, 1, settings.physics_hz),
        &settings,
        std::future::pending()
    ))
    .unwrap();
    tokio::time::sleep(Duration::from_millis(500)).await;
    let _ = stop_tx.send(());
    let (stats, _bus) = within!(detector).unwrap();
    let stats = stats.unwrap();
    assert!(stats.frames >= 30, "{stats:?}");
    // Each front frame was detected with the narrow camera's frame of the same step, or
    // counted as without it.
    assert!(stats.narrow_frames > 0 && stats.narrow_frames + stats.narrow_missing == stats.frames, "{stats:?}");

    let detections = detections.lock().clone();
    let truth = truth.lock().clone();
    let mut matched = 0;
    for (stamp, d) in &detections {
        let Some((_, gt)) = truth.iter().find(|(t, _)| t == stamp) else { continue };
        let lead = gt.objects.iter().find(|o| o.id == 1).unwrap();
        let x = lead.position_in_ego_m[0];
        let nearest = d.detections.iter().min_by(|a, b| (a.distance_m - x).abs().total_cmp(&(b.distance_m - x).abs()));
        let Some(found) = nearest else { continue };
        assert!((found.distance_m - x).abs() / x < 0.05, "stamp {stamp}: {:.2} m vs true {x:.2} m", found.distance_m);
        assert!(d.frame_stamp_pub_ns > 0 && d.frame_stamp_pub_ns <= msg::wall_clock_ns());
        matched += 1;
    }
    assert!(matched >= 30, "{matched} of {} detection messages matched ground truth by time", detections.len());
    // One lead, one track: its id never changes.
    let lead_ids: std::collections::BTreeSet<u32> = detections
        .iter()
        .flat_map(|(_, d)| {
            d.detections.iter().filter(|x| x.distance_m > 30.0 && x.lateral_offset_m.abs() < 1.0).map(|x| x.track_id)
        })
        .collect();
    assert_eq!(lead_ids.len(), 1, "{lead_ids:?}");
}
