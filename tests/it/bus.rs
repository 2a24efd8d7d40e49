//! The bus across two Zenoh sessions on tcp/127.0.0.1 with scouting off.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::Duration;

use crate::common;
use crate::common::{bus_pair, map, TIMEOUT};
use slipstream::msg::{ControlCommand, ImageEncoding, Speed};
use slipstream::topics::{CAMERA_FRONT, VEHICLE_CONTROL, VEHICLE_SPEED};
use slipstream::TopicMap;
use zenoh::Wait;

#[tokio::test(flavor = "multi_thread")]
async fn typed_messages_cross_sessions_with_headers_and_stats() {
    // Blocking, so that every message must arrive: with the default "drop" a put finding the
    // send queue busy for a millisecond (two cores, tests in parallel) is dropped by design.
    let lossless = || map(r#"{ topics: { "vehicle/speed": { congestion_control: "block" } } }"#);
    let (a, b) = bus_pair(lossless(), lossless()).await;
    let sub = b.subscriber(VEHICLE_SPEED).await.unwrap();
    let publisher = a.publisher(VEHICLE_SPEED).await.unwrap();
    assert!(publisher.wait_for_subscriber(TIMEOUT).await);
    for i in 0..5u64 {
        let h = publisher.put(i * 10_000_000, &Speed { speed_mps: i as f64 }).unwrap().unwrap();
        assert_eq!(h.seq, i);
    }
    for i in 0..5u64 {
        let r = within!(sub.recv());
        assert_eq!(r.header.seq, i);
        assert_eq!(r.header.stamp_sim_ns, i * 10_000_000);
        assert_eq!(r.msg, Speed { speed_mps: i as f64 });
        assert!(r.header.stamp_pub_ns > 0);
    }
    let s = sub.stats().snapshot();
    assert_eq!((s.received, s.lost, s.decode_errors), (5, 0, 0));
    assert!(s.latency_p50_us.is_some());
}

#[tokio::test(flavor = "multi_thread")]
async fn namespace_and_remap_select_who_receives() {
    // b shares a's namespace and remap; c has another namespace; d has the default keys.
    let cfg_a = r#"{ namespace: "car1", topics: { "vehicle/speed": { key: "ego/v" } } }"#;
    let (a, b) = bus_pair(map(cfg_a), map(cfg_a)).await;
    let c = slipstream::Bus::from_session(
        common::connected_session(&a.session().info().locators().await[0].to_string()).await,
        map(r#"{ namespace: "car2", topics: { "vehicle/speed": { key: "ego/v" } } }"#),
        "node-c",
    )
    .await
    .unwrap();
    let d = slipstream::Bus::from_session(
        common::connected_session(&a.session().info().locators().await[0].to_string()).await,
        TopicMap::default(),
        "node-d",
    )
    .await
    .unwrap();
    let sub_b = b.subscriber(VEHICLE_SPEED).await.unwrap();
    let sub_c = c.subscriber(VEHICLE_SPEED).await.unwrap();
    let sub_d = d.subscriber(VEHICLE_SPEED).await.unwrap();
    assert_eq!(sub_b.key(), "car1/ego/v");
    let publisher = a.publisher(VEHICLE_SPEED).await.unwrap();
    assert_eq!(publisher.key(), "car1/ego/v");
    assert!(publisher.wait_for_subscriber(TIMEOUT).await);
    publisher.put(0, &Speed { speed_mps: 3.0 }).unwrap();
    assert_eq!(within!(sub_b.recv()).msg.speed_mps, 3.0);
    // Give the others time to have received it if they were (wrongly) matched.
    tokio::time::sleep(Duration::from_millis(500)).await;
    assert!(sub_c.try_recv().is_none(), "another namespace must not receive");
    assert!(sub_d.try_recv().is_none(), "default keys must not receive a remapped topic");
}

#[tokio::test(flavor = "multi_thread")]
async fn configured_qos_reaches_the_wire() {
    let cfg = r#"{ topics: { "vehicle/control": { priority: "interactive-low", express: false, congestion_control: "block" } } }"#;
    let (a, b) = bus_pair(map(cfg), TopicMap::default()).await;
    // Raw zenoh subscribers see the QoS each sample was sent with.
    let seen = Arc::new(parking_lot::Mutex::new(Vec::new()));
    let s2 = seen.clone();
    let _raw = b
        .session()
        .declare_subscriber("**")
        .callback(move |s| {
            s2.lock().push((s.key_expr().to_string(), s.priority(), s.express(), s.congestion_control()))
        })
        .await
        .unwrap();
    let speed = a.publisher(VEHICLE_SPEED).await.unwrap();
    let control = a.publisher(VEHICLE_CONTROL).await.unwrap();
    assert!(speed.wait_for_subscriber(TIMEOUT).await && control.wait_for_subscriber(TIMEOUT).await);
    assert_eq!(control.priority(), zenoh::qos::Priority::InteractiveLow);
    assert_eq!(control.congestion_control(), zenoh::qos::CongestionControl::Block);
    speed.put(0, &Speed { speed_mps: 1.0 }).unwrap();
    control.put(0, &ControlCommand::NEUTRAL).unwrap();
    within!(async {
        while seen.lock().len() < 2 {
            tokio::time::sleep(Duration::from_millis(10)).await;
        }
    });
    let seen = seen.lock().clone();
    let of = |k: &str| seen.iter().find(|s| s.0 == k).cloned().unwrap();
    let (_, p, e, _) = of("vehicle/speed");
    assert_eq!((p, e), (zenoh::qos::Priority::RealTime, true), "default speed QoS");
    let (_, p, e, cc) = of("vehicle/control");
    assert_eq!((p, e, cc), (zenoh::qos::Priority::InteractiveLow, false, zenoh::qos::CongestionControl::Block));
}

/// Lockstep's publishers: from `keep_every_message` on, every topic the config leaves at
/// "drop" blocks instead, frames included; a publisher declared before keeps its QoS.
#[tokio::test(flavor = "multi_thread")]
async fn a_lockstep_bus_blocks_where_the_config_says_drop() {
    let (a, _b) = bus_pair(TopicMap::default(), TopicMap::default()).await;
    let before = a.publisher(VEHICLE_SPEED).await.unwrap();
    assert_eq!(before.congestion_control(), zenoh::qos::CongestionControl::Drop, "the default QoS drops");
    a.keep_every_message();
    let speed = a.publisher(VEHICLE_SPEED).await.unwrap();
    let control = a.publisher(VEHICLE_CONTROL).await.unwrap();
    let frames = a.frame_publisher(slipstream::topics::CAMERA_FRONT).await.unwrap();
    for cc in [speed.congestion_control(), control.congestion_control(), frames.publisher().congestion_control()] {
        assert_eq!(cc, zenoh::qos::CongestionControl::Block);
    }
    assert_eq!(before.congestion_control(), zenoh::qos::CongestionControl::Drop, "declared before: unchanged");
    assert_eq!(speed.priority(), zenoh::qos::Priority::RealTime, "only the congestion control changes");
}

async fn send_frames(bus: &slipstream::Bus, n: u64) -> slipstream::bus::FramePublisher {
    let publisher = bus.frame_publisher(slipstream::topics::CAMERA_FRONT).await.unwrap();
    assert!(publisher.publisher().wait_for_subscriber(TIMEOUT).await);
    for i in 0..n {
        publisher.put_with(i, 4, 2, ImageEncoding::Rgb8, 24, |px| px.fill(i as u8)).unwrap().unwrap();
    }
    publisher
}

#[tokio::test(flavor = "multi_thread")]
async fn latest_only_delivery_keeps_the_newest_and_counts_skips() {
    let (a, b) = bus_pair(TopicMap::default(), TopicMap::default()).await;
    let sub = b.frame_subscriber(slipstream::topics::CAMERA_FRONT).await.unwrap();
    let _p = send_frames(&a, 10).await;
    // Wait until all ten arrived (counted on arrival), then read once.
    within!(async {
        while sub.stats().snapshot().received < 10 {
            tokio::time::sleep(Duration::from_millis(10)).await;
        }
    });
    let s = within!(sub.recv());
    let frame = s.frame();
    assert_eq!(frame.header.seq, 9, "the newest frame");
    assert!(frame.msg.data.iter().all(|&b| b == 9));
    assert!(sub.try_recv().is_none(), "nothing older is left");
    assert_eq!(sub.stats().snapshot().skipped, 9);
}

#[tokio::test(flavor = "multi_thread")]
async fn a_queue_keeps_the_newest_n_in_order() {
    let cfg = r#"{ topics: { "camera/front": { delivery: { queue: 4 } } } }"#;
    let (a, b) = bus_pair(map(cfg), map(cfg)).await;
    let sub = b.subscriber(CAMERA_FRONT).await.unwrap();
    let _p = send_frames(&a, 10).await;
    within!(async {
        while sub.stats().snapshot().received < 10 {
            tokio::time::sleep(Duration::from_millis(10)).await;
        }
    });
    let seqs: Vec<u64> = std::iter::from_fn(|| sub.try_recv().map(|r| r.header.seq)).collect();
    assert_eq!(seqs, vec![6, 7, 8, 9]);
    assert_eq!(sub.stats().snapshot().skipped, 6);
}

#[tokio::test(flavor = "multi_thread")]
async fn frames_go_through_shared_memory_when_enabled() {
    for shm in [true, false] {
        let cfg = format!("{{ camera: {{ shared_memory: {shm} }} }}");
        let (a, b) = bus_pair(map(&cfg), map(&cfg)).await;
        let sub = b.frame_subscriber(slipstream::topics::CAMERA_FRONT).await.unwrap();
        let publisher = a.frame_publisher(slipstream::topics::CAMERA_FRONT).await.unwrap();
        assert_eq!(publisher.uses_shared_memory(), shm);
        assert!(publisher.publisher().wait_for_subscriber(TIMEOUT).await);
        let (w, h) = (640u32, 480u32);
        let sent = publisher
            .put_with(5, w, h, ImageEncoding::Rgb8, (w * h * 3) as usize, |px| {
                px.iter_mut().enumerate().for_each(|(i, b)| *b = (i % 251) as u8)
            })
            .unwrap()
            .unwrap();
        assert_eq!(sent.shared_memory, shm);
        let s = within!(sub.recv());
        assert_eq!(s.is_shared_memory(), shm, "shm={shm}");
        assert_eq!(s.was_joined(), !shm, "in shared memory the frame is one piece; over TCP it is reassembled");
        let f = s.frame();
        assert_eq!((f.msg.width, f.msg.height, f.header.stamp_sim_ns), (w, h, 5));
        assert!(f.msg.data.iter().enumerate().all(|(i, b)| *b == (i % 251) as u8));
    }
}

#[tokio::test(flavor = "multi_thread")]
async fn a_reader_across_a_link_gets_a_link_copy_encoded_only_while_it_reads_it() {
    let (a, b) =
        bus_pair(map(r#"{ camera: { link_copies: ["lz4", "png"] } }"#), map(r#"{ camera: { read: "lz4" } }"#)).await;
    let publisher = a.frame_publisher(slipstream::topics::CAMERA_FRONT).await.unwrap();
    assert_eq!(publisher.copy_keys(), vec!["camera/front/@lz4", "camera/front/@png"]);
    let (w, h) = (160u32, 120u32);
    let put = |stamp: u64| {
        publisher
            .put_with(stamp, w, h, ImageEncoding::Rgb8, (w * h * 3) as usize, |px| {
                px.iter_mut().enumerate().for_each(|(i, b)| *b = ((i / 3 % w as usize) as u64 + stamp) as u8)
            })
            .unwrap()
            .unwrap()
    };
    // Nobody reads a copy yet: the frame goes out, no copy is encoded.
    put(1);
    assert!(!publisher.copies_wanted());
    assert_eq!(publisher.copies_sent(), 0);
    // b reads camera/front/@lz4 (camera.read): only that copy is made, with its frame's header.
    let sub = b.frame_subscriber(slipstream::topics::CAMERA_FRONT).await.unwrap();
    within!(async {
        while !publisher.copies_wanted() {
            tokio::time::sleep(Duration::from_millis(10)).await;
        }
    });
    let sent = put(2);
    let s = within!(sub.recv());
    let f = s.frame();
    assert_eq!(f.msg.encoding, ImageEncoding::Lz4);
    assert_eq!(f.header, sent.header, "a copy carries its frame's header");
    let rgb = f.msg.to_rgb8().unwrap();
    assert!(rgb.iter().enumerate().all(|(i, b)| *b == ((i / 3 % w as usize) as u64 + 2) as u8), "bit-exact");
    assert!(f.msg.data.len() < rgb.len() / 4, "{} bytes of LZ4 for {}", f.msg.data.len(), rgb.len());
    assert_eq!(publisher.copies_sent(), 1, "the png copy has no reader: not encoded");
}

#[tokio::test(flavor = "multi_thread")]
async fn malformed_payloads_are_counted_and_the_stream_goes_on() {
    let (a, b) = bus_pair(TopicMap::default(), TopicMap::default()).await;
    let sub = b.subscriber(VEHICLE_SPEED).await.unwrap();
    let got = Arc::new(AtomicU64::new(0));
    let g = got.clone();
    let cb = b
        .subscribe_with(VEHICLE_SPEED, move |_r| {
            g.fetch_add(1, Ordering::Relaxed);
        })
        .await
        .unwrap();
    let raw = a.session().declare_publisher("vehicle/speed").await.unwrap();
    let typed = a.publisher(VEHICLE_SPEED).await.unwrap();
    assert!(typed.wait_for_subscriber(TIMEOUT).await);
    let good = slipstream::msg::encode(&Default::default(), &Speed { speed_mps: 1.0 });
    let bad: Vec<Vec<u8>> = vec![
        vec![],
        vec![0xff; 40],
        good[..good.len() - 3].to_vec(),
        [good.clone(), vec![0]].concat(),
        slipstream::msg::encode(&Default::default(), &ControlCommand::NEUTRAL),
    ];
    for payload in &bad {
        raw.put(payload.clone()).wait().unwrap();
    }
    typed.put(1, &Speed { speed_mps: 2.0 }).unwrap();
    // The good message is real-time priority and may overtake the bad ones (default
    // priority): wait for both.
    let r = within!(sub.recv());
    assert_eq!(r.msg.speed_mps, 2.0, "the good message gets through");
    within!(async {
        while sub.stats().snapshot().decode_errors < bad.len() as u64 {
            tokio::time::sleep(Duration::from_millis(10)).await;
        }
    });
    let s = sub.stats().snapshot();
    assert_eq!((s.decode_errors, s.received), (bad.len() as u64, 1), "{s:?}");
    assert!(s.latency_p99_us.unwrap() < 10e6, "bad payloads never reach the latency figures: {s:?}");
    within!(async {
        while got.load(Ordering::Relaxed) < 1 || cb.stats().snapshot().decode_errors < bad.len() as u64 {
            tokio::time::sleep(Duration::from_millis(10)).await;
        }
    });
    assert_eq!(got.load(Ordering::Relaxed), 1);
}

#[tokio::test(flavor = "multi_thread")]
async fn rate_limit_judges_simulation_time() {
    // Blocking congestion control: the 20 messages go out back to back, and on a loaded
    // machine dropping one (vehicle/speed's default) would be a loss this test does not judge.
    let cfg = r#"{ topics: { "vehicle/speed": { max_rate_hz: 20, congestion_control: "block" } } }"#;
    let (a, b) = bus_pair(map(cfg), map(cfg)).await;
    let sub = b.subscriber(VEHICLE_SPEED).await.unwrap();
    let publisher = a.publisher(VEHICLE_SPEED).await.unwrap();
    assert!(publisher.wait_for_subscriber(TIMEOUT).await);
    // 100 messages, 10 ms of simulation time apart, sent as fast as possible: 1 s at 20 Hz.
    let sent =
        (0..100u64).filter(|i| publisher.put(i * 10_000_000, &Speed { speed_mps: 0.0 }).unwrap().is_some()).count();
    assert_eq!(sent, 20);
    // Counted on arrival (before the subscriber's 16-deep queue): all 20, no gap in seq.
    within!(async {
        while sub.stats().snapshot().received < 20 {
            tokio::time::sleep(Duration::from_millis(10)).await;
        }
    });
    let s = sub.stats().snapshot();
    assert_eq!((s.received, s.lost, s.restarts), (20, 0, 0), "rate-limited messages take no seq: {s:?}");
    let newest = std::iter::from_fn(|| sub.try_recv()).last().unwrap();
    assert_eq!(newest.header.seq, 19);
}

#[tokio::test(flavor = "multi_thread")]
async fn liveliness_lists_the_nodes_alive() {
    let (a, b) = bus_pair(map(r#"{ namespace: "rig" }"#), map(r#"{ namespace: "rig" }"#)).await;
    let mut nodes = Vec::new();
    within!(async {
        loop {
            nodes = a.nodes_alive().await.unwrap();
            if nodes.len() == 2 {
                break;
            }
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
    });
    assert_eq!(nodes, vec!["node-a".to_string(), "node-b".to_string()]);
    b.close().await.unwrap();
    within!(async {
        while a.nodes_alive().await.unwrap() != vec!["node-a".to_string()] {
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
    });
}

#[tokio::test(flavor = "multi_thread")]
async fn a_late_subscriber_gets_the_latched_camera_info() {
    use slipstream::msg::CameraInfo;
    use slipstream::topics::CAMERA_FRONT_INFO;
    let (a, b) = bus_pair(TopicMap::default(), TopicMap::default()).await;
    let publisher = a.publisher(CAMERA_FRONT_INFO).await.unwrap();
    assert!(publisher.is_latched());
    let info = |w| CameraInfo::pinhole(w, 480, 1.0, [1.5, 0.0, 1.4], [0.0; 3], 20.0, ImageEncoding::Rgb8);
    // Published before anyone subscribes: only the latest is kept.
    publisher.put(1, &info(320)).unwrap();
    publisher.put(2, &info(640)).unwrap();
    tokio::time::sleep(Duration::from_millis(200)).await;
    let late = b.subscriber(CAMERA_FRONT_INFO).await.unwrap();
    let r = within!(late.recv());
    assert_eq!((r.msg.width, r.header.seq), (640, 1), "the last message published before the subscriber existed");
    // And a non-latched topic does not replay.
    let speed = a.publisher(VEHICLE_SPEED).await.unwrap();
    speed.put(0, &Speed { speed_mps: 1.0 }).unwrap();
    tokio::time::sleep(Duration::from_millis(200)).await;
    let late_speed = b.subscriber(VEHICLE_SPEED).await.unwrap();
    assert!(late_speed.recv_timeout(Duration::from_millis(500)).await.is_none());
}

#[tokio::test(flavor = "multi_thread")]
async fn jpeg_camera_encoding_from_config() {
    let cfg = r#"{ camera: { encoding: "jpeg", jpeg_quality: 90 } }"#;
    let (a, b) = bus_pair(map(cfg), map(cfg)).await;
    let sub = b.frame_subscriber(slipstream::topics::CAMERA_FRONT).await.unwrap();
    let publisher = a.frame_publisher(slipstream::topics::CAMERA_FRONT).await.unwrap();
    assert_eq!(publisher.encoding(), ImageEncoding::Jpeg);
    assert!(publisher.publisher().wait_for_subscriber(TIMEOUT).await);
    let (w, h) = (64u32, 48u32);
    // A smooth gradient: JPEG keeps it within a few levels.
    let rgb: Vec<u8> = (0..w * h).flat_map(|i| [(i % w * 4) as u8, (i / w * 5) as u8, 128]).collect();
    publisher.put_rgb(7, w, h, &rgb).unwrap().unwrap();
    let s = within!(sub.recv());
    let f = s.frame();
    assert_eq!((f.msg.encoding, f.msg.width, f.msg.height), (ImageEncoding::Jpeg, w, h));
    assert!(f.msg.data.len() < rgb.len() / 4, "compressed: {} bytes", f.msg.data.len());
    let decoded = f.msg.to_rgb8().unwrap();
    assert_eq!(decoded.len(), rgb.len());
    let worst = decoded.iter().zip(&rgb).map(|(x, y)| (*x as i32 - *y as i32).abs()).max().unwrap();
    assert!(worst <= 24, "JPEG at quality 90 stays close to the original: worst {worst}");
    // Raw frames come back borrowed, unchanged; a frame whose JPEG is garbage is an error.
    let raw = slipstream::msg::CameraFrameRef {
        width: 2,
        height: 1,
        encoding: ImageEncoding::Rgb8,
        data: &[1, 2, 3, 4, 5, 6],
    };
    assert!(matches!(raw.to_rgb8().unwrap(), std::borrow::Cow::Borrowed(_)));
    let bad =
        slipstream::msg::CameraFrameRef { width: 2, height: 1, encoding: ImageEncoding::Jpeg, data: &[0xff, 0xd8, 0] };
    assert!(bad.to_rgb8().is_err());
}

/// A node's two sessions as `Bus::open_node` opens them: the low-latency config derived from
/// a loopback peer config (a unix socket: the twin socket is derived on both sides).
fn two_session_configs(listen: &str, connect: &[String]) -> (zenoh::Config, Option<zenoh::Config>) {
    let mut main = zenoh::Config::default();
    for (k, v) in [
        ("mode", "\"peer\"".to_string()),
        ("scouting/multicast/enabled", "false".into()),
        ("scouting/gossip/enabled", "false".into()),
        ("listen/endpoints", serde_json::to_string(&[listen]).unwrap()),
        ("connect/endpoints", serde_json::to_string(connect).unwrap()),
    ] {
        main.insert_json5(k, &v).unwrap();
    }
    let ll = slipstream::config::low_latency_config(&main, &Default::default()).unwrap();
    (main, ll)
}

#[tokio::test(flavor = "multi_thread")]
async fn real_time_topics_ride_the_low_latency_session_and_plain_sessions_still_see_them() {
    let dir = std::env::temp_dir().join(format!("slipstream-ll-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let sock = |n: &str| format!("unixsock-stream/{}", dir.join(format!("{n}.sock")).display());
    let lossless = || map(r#"{ topics: { "vehicle/speed": { congestion_control: "block" } } }"#);
    let (main_a, ll_a) = two_session_configs(&sock("a"), &[]);
    let a = slipstream::Bus::open_sessions(main_a, ll_a, lossless(), "node-a").await.unwrap();
    let (main_b, ll_b) = two_session_configs(&sock("b"), &[sock("a")]);
    let b = slipstream::Bus::open_sessions(main_b, ll_b, lossless(), "node-b").await.unwrap();
    let (a_ll, b_ll) = (a.low_latency_session().unwrap(), b.low_latency_session().unwrap());

    // An ordinary Zenoh session (no low-latency transport: what Python, record or a router
    // run) dials A's low-latency session only, and subscribes to the raw key.
    let plain = common::connected_session(&format!("{}.ll", sock("a"))).await;
    let plain_got = Arc::new(AtomicU64::new(0));
    let counter = plain_got.clone();
    let _raw = plain.declare_subscriber("vehicle/speed").callback(move |_| {
        counter.fetch_add(1, Ordering::Relaxed);
    });
    let _raw = _raw.await.unwrap();

    let sub = b.subscriber(VEHICLE_SPEED).await.unwrap();
    let publisher = a.publisher(VEHICLE_SPEED).await.unwrap();
    assert!(publisher.wait_for_subscriber(TIMEOUT).await);
    // B's low-latency session is linked with A's (the derived twin sockets), and the speed
    // comes over that link.
    let peers: Vec<_> = b_ll.info().peers_zid().await.collect();
    assert!(peers.contains(&a_ll.zid()), "B's low-latency session is not linked with A's: {peers:?}");
    within!(async {
        let mut i = 0u64;
        while plain_got.load(Ordering::Relaxed) == 0 || sub.stats().snapshot().received == 0 {
            publisher.put(i * 10_000_000, &Speed { speed_mps: 20.0 }).unwrap();
            i += 1;
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
    });
    assert_eq!(within!(sub.recv()).msg.speed_mps, 20.0);
    // Frames stay on the main session: B (main linked with A's main) gets them, the plain
    // session linked with A's low-latency session only does not.
    let plain_frames = Arc::new(AtomicU64::new(0));
    let counter = plain_frames.clone();
    let _raw_frames = plain
        .declare_subscriber("camera/front")
        .callback(move |_| {
            counter.fetch_add(1, Ordering::Relaxed);
        })
        .await
        .unwrap();
    let frames_in = b.frame_subscriber(CAMERA_FRONT).await.unwrap();
    let frames = a.frame_publisher(CAMERA_FRONT).await.unwrap();
    assert!(frames.publisher().wait_for_subscriber(TIMEOUT).await);
    within!(async {
        let mut i = 0u64;
        while frames_in.try_recv().is_none() {
            frames.put_with(i * 50_000_000, 4, 2, ImageEncoding::Rgb8, 24, |px| px[0] = 1).unwrap();
            i += 1;
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
    });
    assert_eq!(plain_frames.load(Ordering::Relaxed), 0, "a frame went out on the low-latency session");
    drop(frames);
    plain.close().await.unwrap();
    b.close().await.unwrap();
    a.close().await.unwrap();
    let _ = std::fs::remove_dir_all(&dir);
}

/// A node's bus is seen (its liveliness token) only once it announces, after declaring its
/// subscriptions: whoever sees the token and sends at once reaches them. The simulator in
/// lockstep sends its first step on seeing the nodes it waits for.
#[tokio::test(flavor = "multi_thread")]
async fn a_node_is_seen_once_it_announces_and_whoever_sees_it_reaches_its_subscribers() {
    use slipstream::msg::{SimEvent, SimEventKind};
    use slipstream::topics::SIM_EVENTS;
    let (s, ep) = common::listening_session().await;
    let observer = slipstream::Bus::from_session(s, TopicMap::default(), "observer").await.unwrap();
    let connect = slipstream::config::ConnectArgs {
        connect: vec![ep],
        listen: vec!["tcp/127.0.0.1:0".into()],
        cfg: vec!["scouting/gossip/enabled:false".into()],
        ..Default::default()
    };
    let node = slipstream::Bus::open_node(&connect, &Default::default(), "late-node").await.unwrap();
    let events = node.subscriber(SIM_EVENTS).await.unwrap();
    let publisher = observer.publisher(SIM_EVENTS).await.unwrap();
    tokio::time::sleep(Duration::from_millis(300)).await;
    assert_eq!(observer.nodes_alive().await.unwrap(), vec!["observer".to_string()], "seen before announcing");
    node.announce().await.unwrap();
    node.announce().await.unwrap();
    within!(async {
        while !observer.nodes_alive().await.unwrap().contains(&"late-node".to_string()) {
            tokio::time::sleep(Duration::from_millis(10)).await;
        }
    });
    publisher.put(0, &SimEvent { kind: SimEventKind::ScenarioStart { name: "first".into(), seed: 1 } }).unwrap();
    let first = events.recv_timeout(TIMEOUT).await.expect("the first message after the token was seen");
    assert!(matches!(first.msg.kind, SimEventKind::ScenarioStart { ref name, .. } if name == "first"));
    node.leave().await;
}
