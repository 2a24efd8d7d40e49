//! Recording and playback through the library: what a publisher sends is recorded byte for
//! byte with its publisher's name, and played back into another namespace whole and in order.
//! (tests/python/test_record.py reads recordings with an independent MCAP reader.)

use std::sync::{Arc, Mutex};
use std::time::Duration;

use slipstream::msg::{Speed, VehicleState};
use slipstream::record::{play, Pace, PlayOptions, Recording};
use slipstream::{topics, Bus};

use crate::common;

/// (key, payload, attachment) of every sample seen.
type Seen = Arc<Mutex<Vec<(String, Vec<u8>, Option<String>)>>>;

fn state(step: u64) -> VehicleState {
    VehicleState {
        step,
        position_in_world_m: [step as f64, 0.0, 0.0],
        yaw_in_world_rad: 0.0,
        pitch_rad: 0.0,
        roll_rad: 0.0,
        velocity_in_world_mps: [20.0, 0.0, 0.0],
        acceleration_in_body_mps2: [0.0; 3],
        yaw_rate_radps: 0.0,
        speed_mps: 20.0,
        lane: 1,
        applied: slipstream::msg::ControlCommand::NEUTRAL,
        control_timing: None,
    }
}

async fn watch(bus: &Bus, selector: &str, seen: &Seen) -> slipstream::bus::Declared {
    let seen = seen.clone();
    let key = zenoh::key_expr::OwnedKeyExpr::autocanonize(selector.to_string()).unwrap();
    bus.subscribe_samples(key, false, move |s| {
        let from = s.attachment().and_then(|a| a.try_to_string().ok()).map(|a| a.into_owned());
        seen.lock().unwrap().push((s.key_expr().to_string(), s.payload().to_bytes().into_owned(), from));
    })
    .await
    .unwrap()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_recording_plays_back_whole_in_order_into_another_namespace() {
    let dir = std::env::temp_dir().join(format!("slipstream-record-test-{}", std::process::id()));
    let path = dir.join("run.mcap");
    within!(async {
        // Record what a "sim" node publishes.
        let (recorder_bus, sim_bus) = common::bus_pair(Default::default(), Default::default()).await;
        let sim_bus = Bus::from_session(sim_bus.session().clone(), Default::default(), "sim").await.unwrap();
        let recording = Recording::start(&recorder_bus, &recorder_bus.topics().every_key(), &path).await.unwrap();
        let speed = sim_bus.publisher(topics::VEHICLE_SPEED).await.unwrap();
        let states = sim_bus.publisher(topics::VEHICLE_STATE).await.unwrap();
        assert!(speed.wait_for_subscriber(common::TIMEOUT).await);
        let sent: Seen = Arc::default();
        let _mine = watch(&recorder_bus, "vehicle/**", &sent).await;
        for k in 0..50u64 {
            speed.put(k * 10_000_000, &Speed { speed_mps: k as f64 }).unwrap();
            states.put(k * 10_000_000, &state(k)).unwrap();
            tokio::time::sleep(Duration::from_millis(2)).await;
        }
        while sent.lock().unwrap().len() < 100 {
            tokio::time::sleep(Duration::from_millis(10)).await;
        }
        let summary = tokio::task::spawn_blocking(move || recording.finish()).await.unwrap().unwrap();
        assert_eq!(summary.messages, 100, "{summary:?}");
        assert!(!summary.lost_anything(), "{summary:?}");
        for c in &summary.channels {
            assert_eq!((c.messages, c.publisher.as_deref()), (50, Some("sim")), "{c:?}");
        }

        // Play it, as fast as the subscriber takes it, into the namespace "replay".
        let replay_map = slipstream::TopicMap::default().with_namespace("replay").unwrap();
        let (player_bus, viewer_bus) = common::bus_pair(replay_map, Default::default()).await;
        let got: Seen = Arc::default();
        let _viewer = watch(&viewer_bus, "replay/**", &got).await;
        tokio::time::sleep(Duration::from_millis(300)).await; // the subscription reaches the player
        let options = PlayOptions { pace: Pace::Max, start_s: 0.0, keys: Vec::new() };
        let player = Arc::new(player_bus);
        let p = player.clone();
        let report = tokio::task::spawn_blocking(move || play(&p, &path, &options, |_| {})).await.unwrap().unwrap();
        assert_eq!(report.messages, 100);
        while got.lock().unwrap().len() < 100 {
            tokio::time::sleep(Duration::from_millis(10)).await;
        }
        let sent = sent.lock().unwrap().clone();
        let got = got.lock().unwrap().clone();
        for key in ["vehicle/speed", "vehicle/state"] {
            // The recorded publisher, marked as a replay (sim@replay): no live node follows it.
            let before: Vec<_> = sent
                .iter()
                .filter(|s| s.0 == key)
                .map(|s| (s.1.clone(), s.2.as_deref().map(slipstream::bus::replayed_name)))
                .collect();
            let after: Vec<_> =
                got.iter().filter(|s| s.0 == format!("replay/{key}")).map(|s| (s.1.clone(), s.2.clone())).collect();
            assert_eq!(before.len(), 50, "{key}");
            assert_eq!(before, after, "{key}: the same payloads from the same publisher, replayed, in the same order");
        }

        // At the recorded pace (and twice as fast) no message goes out before its time: the
        // playback spans the recording (/ the rate). Upper bounds only catch a hang: a loaded
        // machine may play late, never early.
        for rate in [1.0, 2.0] {
            let options = PlayOptions { pace: Pace::Rate(rate), start_s: 0.0, keys: Vec::new() };
            let (p, file) = (player.clone(), dir.join("run.mcap"));
            let report = tokio::task::spawn_blocking(move || play(&p, &file, &options, |_| {})).await.unwrap().unwrap();
            assert_eq!(report.messages, 100);
            assert!(report.recorded_s > 0.09, "50 steps 2 ms apart at least: {report:?}");
            assert!(report.wall_s >= report.recorded_s / rate, "rate {rate}: {report:?}");
            assert!(report.wall_s < report.recorded_s / rate + 10.0, "rate {rate}: {report:?}");
        }
    });
    let _ = std::fs::remove_dir_all(&dir);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn play_skips_by_key_and_plays_a_cut_file_up_to_the_cut() {
    let dir = std::env::temp_dir().join(format!("slipstream-play-test-{}", std::process::id()));
    let path = dir.join("run.mcap");
    within!(async {
        let (recorder_bus, sim_bus) = common::bus_pair(Default::default(), Default::default()).await;
        let recording = Recording::start(&recorder_bus, &recorder_bus.topics().every_key(), &path).await.unwrap();
        let speed = sim_bus.publisher(topics::VEHICLE_SPEED).await.unwrap();
        let states = sim_bus.publisher(topics::VEHICLE_STATE).await.unwrap();
        assert!(speed.wait_for_subscriber(common::TIMEOUT).await);
        let mut first_chunk_end = 0;
        for batch in 0..2u64 {
            for k in batch * 10..batch * 10 + 10 {
                speed.put(k * 10_000_000, &Speed { speed_mps: k as f64 }).unwrap();
                states.put(k * 10_000_000, &state(k)).unwrap();
                tokio::time::sleep(Duration::from_millis(5)).await;
            }
            // The writer ends its chunk every second: the first batch is then whole on disk.
            tokio::time::sleep(slipstream::record::FLUSH_EVERY * 5 / 2).await;
            if batch == 0 {
                first_chunk_end = std::fs::metadata(&path).unwrap().len() as usize;
            }
        }
        let summary = tokio::task::spawn_blocking(move || recording.finish()).await.unwrap().unwrap();
        assert_eq!(summary.messages, 40, "{summary:?}");

        let bus = Arc::new(recorder_bus);
        let only_speed = PlayOptions {
            pace: Pace::Rate(50.0),
            start_s: 0.0,
            keys: vec![zenoh::key_expr::OwnedKeyExpr::autocanonize("vehicle/speed".to_string()).unwrap()],
        };
        let (b, p) = (bus.clone(), path.clone());
        let report = tokio::task::spawn_blocking(move || play(&b, &p, &only_speed, |_| {})).await.unwrap().unwrap();
        assert_eq!((report.messages, report.skipped), (20, 20), "{report:?}");

        // A file cut inside its second chunk (a crash): the first chunk plays, and the report
        // says the file was cut.
        let bytes = std::fs::read(&path).unwrap();
        assert!(first_chunk_end > 0 && first_chunk_end + 20 < bytes.len());
        let cut = dir.join("cut.mcap");
        std::fs::write(&cut, &bytes[..first_chunk_end + 20]).unwrap();
        let all = PlayOptions { pace: Pace::Max, start_s: 0.0, keys: Vec::new() };
        let b = bus.clone();
        let report = tokio::task::spawn_blocking(move || play(&b, &cut, &all, |_| {})).await.unwrap().unwrap();
        assert!(report.cut, "{report:?}");
        assert_eq!(report.messages, 20, "the first chunk's messages: {report:?}");
    });
    let _ = std::fs::remove_dir_all(&dir);
}
