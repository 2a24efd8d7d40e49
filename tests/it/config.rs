//! Topic map and Zenoh config: defaults, namespace, remapping, QoS, and errors that name the
//! file, the key and the fix.

use slipstream::config::{ConnectArgs, TopicMap};
use slipstream::qos::{Congestion, Delivery, Priority};
use slipstream::topics::Topic;

#[test]
fn defaults_give_logical_names_and_control_qos() {
    let m = TopicMap::default();
    assert_eq!(m.key(Topic::VehicleSpeed).as_str(), "vehicle/speed");
    assert_eq!(m.key(Topic::CameraFrontInfo).as_str(), "camera/front/info");
    let speed = m.qos(Topic::VehicleSpeed);
    assert_eq!((speed.priority, speed.express), (Priority::RealTime, true));
    let cam = m.qos(Topic::CameraFront);
    assert_eq!((cam.congestion_control, cam.delivery), (Congestion::Drop, Delivery::Latest));
    assert!(cam.priority != Priority::RealTime);
}

#[test]
fn namespace_and_remapping() {
    let m = TopicMap::from_json5(
        r#"{
            namespace: "car1",
            topics: {
                "vehicle/speed": { key: "ego/v" },
                "sim/clock": { key: "/fleet/clock" },   // absolute: no namespace
                "camera/front": { delivery: { queue: 3 }, max_rate_hz: 10, priority: "background" },
            },
        }"#,
        "t.json5",
    )
    .unwrap();
    assert_eq!(m.key(Topic::VehicleSpeed).as_str(), "car1/ego/v");
    assert_eq!(m.key(Topic::SimClock).as_str(), "fleet/clock");
    assert_eq!(m.key(Topic::Objects).as_str(), "car1/objects");
    let cam = m.qos(Topic::CameraFront);
    assert_eq!((cam.delivery, cam.max_rate_hz, cam.priority), (Delivery::Queue(3), Some(10.0), Priority::Background));
    assert_eq!(m.node_key("sim").unwrap().as_str(), "car1/nodes/sim");
    assert_eq!(m.topic_of(zenoh::key_expr::keyexpr::new("car1/ego/v").unwrap()), Some(Topic::VehicleSpeed));
    // --namespace replaces the file's namespace.
    let m = m.with_namespace("car2").unwrap();
    assert_eq!(m.key(Topic::VehicleSpeed).as_str(), "car2/ego/v");
}

fn err(text: &str) -> String {
    TopicMap::from_json5(text, "config/slipstream.json5").unwrap_err().to_string()
}

#[test]
fn errors_name_file_key_and_what_is_allowed() {
    let e = err(r#"{ topics: { "vehicle/speed": { priority: "fast" } } }"#);
    assert!(e.starts_with("config/slipstream.json5: key `topics.vehicle/speed.priority`"), "{e}");
    assert!(e.contains("real-time") && e.contains("background"), "lists the allowed values: {e}");

    let e = err(r#"{ topics: { "vehicle/sped": {} } }"#);
    assert!(e.contains("`topics.vehicle/sped`") && e.contains("unknown topic") && e.contains("vehicle/speed"), "{e}");

    let e = err(r#"{ topics: { "objects": { prio: "data" } } }"#);
    assert!(e.contains("`topics.objects.prio`") || e.contains("`topics.objects`"), "{e}");
    assert!(e.contains("unknown field `prio`"), "{e}");

    let e = err(r#"{ camera: { jpeg_quality: 0 } }"#);
    assert!(e.contains("`camera.jpeg_quality`") && e.contains("1 to 100"), "{e}");

    let e = err(r#"{ camera: { read: "webp" } }"#);
    assert!(e.contains("`camera.read`") && e.contains("\"published\"") && e.contains("\"lz4\""), "{e}");

    let e = err(r#"{ camera: { link_copies: ["lz4", "gif"] } }"#);
    assert!(e.contains("camera.link_copies") && e.contains("gif"), "{e}");

    let e = err(r#"{ topics: { "objects": { key: "a/*/b" } } }"#);
    assert!(e.contains("`topics.objects.key`") && e.contains("wildcard"), "{e}");

    let e = err(r#"{ topics: { "objects": { delivery: { queue: 0 } } } }"#);
    assert!(e.contains("`topics.objects.delivery`"), "{e}");

    let e = err(r#"{ topics: { "objects": { max_rate_hz: -1 } } }"#);
    assert!(e.contains("max_rate_hz") && e.contains("positive"), "{e}");

    let e = err(r#"{ namespace: "a/**" }"#);
    assert!(e.contains("`namespace`"), "{e}");

    let e = err(r#"{ topics: { "#);
    assert!(e.starts_with("config/slipstream.json5: not valid JSON5"), "{e}");

    let e = TopicMap::load(std::path::Path::new("/nonexistent/slipstream.json5")).unwrap_err().to_string();
    assert!(e.contains("/nonexistent/slipstream.json5") && e.contains("cannot read"), "{e}");
}

fn repo_file(rel: &str) -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(rel)
}

#[test]
fn shipped_topic_config_is_the_defaults() {
    let m = TopicMap::load(&repo_file("config/slipstream.json5")).unwrap();
    for t in Topic::ALL {
        assert_eq!(m.key(t), TopicMap::default().key(t));
        assert_eq!(m.qos(t), t.default_qos(), "{t}: the file documents the defaults");
    }
}

#[test]
fn shipped_zenoh_configs_parse() {
    for f in ["config/zenoh.json5", "config/lan-peer.json5", "config/client.json5", "config/router.json5"] {
        let args = ConnectArgs { zenoh_config: Some(repo_file(f)), ..Default::default() };
        args.zenoh_config().unwrap_or_else(|e| panic!("{f}: {e}"));
    }
    // The default keeps everything on this machine.
    let c = ConnectArgs::default().zenoh_config().unwrap();
    assert_eq!(c.get_json("scouting/multicast/enabled").unwrap(), "false");
    assert!(c.get_json("listen/endpoints").unwrap().contains("127.0.0.1"));
    // Small socket buffers, so real-time messages do not queue behind frames in the kernel.
    assert_eq!(c.get_json("transport/link/tcp/so_sndbuf").unwrap(), "65536");
    assert_eq!(c.get_json("transport/link/tcp/so_rcvbuf").unwrap(), "65536");
    // The lan-peer config turns multicast scouting on, the router listens beyond loopback.
    let lan = ConnectArgs { zenoh_config: Some(repo_file("config/lan-peer.json5")), ..Default::default() };
    assert_eq!(lan.zenoh_config().unwrap().get_json("scouting/multicast/enabled").unwrap(), "true");
}

#[test]
fn connection_flags_override_the_file() {
    let args = ConnectArgs {
        mode: Some(slipstream::config::ModeArg::Client),
        connect: vec!["tcp/127.0.0.1:7500".into()],
        listen: vec!["tcp/127.0.0.1:7501".into()],
        cfg: vec!["transport/shared_memory/enabled:false".into()],
        ..Default::default()
    };
    let c = args.zenoh_config().unwrap();
    assert_eq!(c.get_json("mode").unwrap(), "\"client\"");
    assert!(c.get_json("connect/endpoints").unwrap().contains("7500"));
    assert!(c.get_json("listen/endpoints").unwrap().contains("7501"));
    assert_eq!(c.get_json("transport/shared_memory/enabled").unwrap(), "false");

    let bad = ConnectArgs { cfg: vec!["transport/shared_memory/enabled:maybe".into()], ..Default::default() };
    let e = bad.zenoh_config().unwrap_err().to_string();
    assert!(e.contains("--cfg") && e.contains("transport/shared_memory/enabled") && e.contains("maybe"), "{e}");
    let bad = ConnectArgs { cfg: vec!["no-colon".into()], ..Default::default() };
    assert!(bad.zenoh_config().unwrap_err().to_string().contains("KEY:VALUE"));
    let missing = ConnectArgs { zenoh_config: Some("/nonexistent/z.json5".into()), ..Default::default() };
    let e = missing.zenoh_config().unwrap_err().to_string();
    assert!(e.contains("/nonexistent/z.json5") && e.contains("no such file"), "{e}");
}

#[test]
fn a_node_reading_a_link_copy_watches_every_topic_at_its_read_key_not_the_whole_namespace() {
    let all = |m: &TopicMap| m.every_key().iter().map(|k| k.to_string()).collect::<Vec<_>>();
    assert_eq!(all(&crate::common::map("{ namespace: \"car1\" }")), vec!["car1/**"]);
    let remote = crate::common::map(r#"{ namespace: "car1", camera: { read: "lz4" } }"#);
    let keys = all(&remote);
    assert!(keys.contains(&"car1/camera/front/@lz4".to_string()), "{keys:?}");
    assert!(keys.contains(&"car1/camera/narrow/@lz4".to_string()), "{keys:?}");
    assert!(
        keys.contains(&"car1/vehicle/speed".to_string()) && keys.contains(&"car1/nodes/**".to_string()),
        "{keys:?}"
    );
    // Nothing that would match the raw frames: `**` would pull them across the link.
    for k in &keys {
        let ke = zenoh::key_expr::KeyExpr::try_from(k.as_str()).unwrap();
        assert!(!ke.intersects(&zenoh::key_expr::KeyExpr::try_from("car1/camera/front").unwrap()), "{k}");
    }
}

#[test]
fn a_loop_in_the_default_namespace_watches_its_own_keys_not_the_other_loops() {
    let keys = |m: &TopicMap| m.every_key().iter().map(|k| k.to_string()).collect::<Vec<_>>();
    let default = keys(&crate::common::map("{}"));
    assert!(default.contains(&"vehicle/speed".to_string()) && default.contains(&"nodes/**".to_string()), "{default:?}");
    for k in &default {
        let ke = zenoh::key_expr::KeyExpr::try_from(k.as_str()).unwrap();
        let other = zenoh::key_expr::KeyExpr::try_from("loop-2/vehicle/speed").unwrap();
        assert!(!ke.intersects(&other), "{k} would take the loop in loop-2");
    }
    // In a namespace of its own, the whole namespace is the loop's.
    assert_eq!(keys(&crate::common::map("{ namespace: \"car1\" }")), vec!["car1/**"]);
}

#[test]
fn an_unknown_cfg_key_is_named_as_a_key_with_the_fix() {
    let args = ConnectArgs { cfg: vec!["nosuch/key:1".into()], ..Default::default() };
    let e = args.zenoh_config().unwrap_err().to_string();
    assert!(e.contains("nosuch/key") && e.contains("no such Zenoh config key") && e.contains("--cfg '"), "{e}");
    assert!(!e.contains("Str("), "{e}");
}

#[test]
fn an_ip_endpoint_without_its_port_is_refused_with_the_fix() {
    for (connect, listen) in [(vec!["tcp/127.0.0.1".to_string()], vec![]), (vec![], vec!["tcp/[::1]".to_string()])] {
        let flag = if connect.is_empty() { "-l/--listen" } else { "-e/--connect" };
        let args = ConnectArgs { connect, listen, ..Default::default() };
        let e = args.zenoh_config().unwrap_err().to_string();
        assert!(e.contains(flag) && e.contains("no port") && e.contains(":7447"), "{e}");
    }
    for fine in ["tcp/127.0.0.1:7447", "tcp/[::1]:0", "udp/localhost:7447", "unixsock-stream//tmp/slipstream.sock"] {
        let args = ConnectArgs { connect: vec![fine.into()], ..Default::default() };
        assert!(args.zenoh_config().is_ok(), "{fine}");
    }
}
