"""ROS 2 sees the loop: `slipstream up --ros2` and `slipstream ros2`, checked with code we did not
write. zenoh-ros2-sdk lists the graph from the liveliness tokens (as `ros2 topic list -t` does),
rosbags computes the type hashes and decodes every message's CDR, and zenoh-ros2-sdk's attachment
class reads rmw_zenoh's attachment. No ROS 2 install: these are the libraries ROS tooling outside
ROS uses. rosbags has no ackermann_msgs; that one type is registered from our definition, so
its hash is checked for the hashing, not for the definition (docs/ros2.md says so)."""

import json
import signal
import subprocess
import sys
import threading
import time

import pytest
import zenoh
import zenoh.ext
from conftest import ROOT, peer_config

from slipstream_client import decode

rosbags_typesys = pytest.importorskip("rosbags.typesys")
sdk_discovery = pytest.importorskip("zenoh_ros2_sdk.discovery")
from zenoh_ros2_sdk.attachment import Attachment  # noqa: E402
from zenoh_ros2_sdk.keyexpr import topic_keyexpr  # noqa: E402

JAZZY = rosbags_typesys.Stores.ROS2_JAZZY


def types_of(slipstream_bin):
    out = subprocess.run([slipstream_bin, "ros2", "--list", "--types", "--json"], capture_output=True, text=True,
                         check=True, cwd=ROOT)
    return json.loads(out.stdout)


def typestore(slipstream_bin):
    """rosbags' Jazzy store, plus the types it lacks (ackermann_msgs) from our definitions."""
    ts = rosbags_typesys.get_typestore(JAZZY)
    extra = {}
    for row in types_of(slipstream_bin):
        if row["type"] not in ts.types:
            extra.update(rosbags_typesys.get_types_from_msg(row["definition"].split("\n====")[0], row["type"]))
    ts.register(extra)
    return ts


def test_every_type_hash_is_the_one_rosbags_computes(slipstream_bin):
    rows = types_of(slipstream_bin)
    ts = typestore(slipstream_bin)
    assert len(rows) >= 20
    for row in rows:
        assert row["hash"] == ts.hash_rihs01(row["type"]), row["type"]
        assert row["dds"] == row["type"].replace("/msg/", "::msg::dds_::").replace("/", "::") + "_"


class Collector:
    """Samples per key expression, decoded by `decode(sample)`; at most `keep` each."""

    def __init__(self, keep=30):
        self.lock = threading.Lock()
        self.got = {}
        self.keep = keep

    def handler(self, name, decode_fn):
        def on_sample(sample):
            item = decode_fn(sample)
            with self.lock:
                items = self.got.setdefault(name, [])
                items.append(item)
                del items[:-self.keep]
        return on_sample

    def count(self, name):
        with self.lock:
            return len(self.got.get(name, []))

    def items(self, name):
        with self.lock:
            return list(self.got.get(name, []))


def ros_decoder(ts, type_name):
    def decode_fn(sample):
        att = sample.attachment
        return ts.deserialize_cdr(sample.payload.to_bytes(), type_name), Attachment.from_bytes(att.to_bytes())
    return decode_fn


def wait_for(predicate, proc, seconds):
    deadline = time.time() + seconds
    while time.time() < deadline:
        if predicate():
            return True
        if proc.poll() is not None:
            raise AssertionError(f"the process ended early: {proc.stderr.read() if proc.stderr else ''}")
        time.sleep(0.2)
    return False


ROUTES = {
    "image": ("camera/front/image_raw", "sensor_msgs/msg/Image"),
    "odometry": ("vehicle/odometry", "nav_msgs/msg/Odometry"),
    "tf": ("tf", "tf2_msgs/msg/TFMessage"),
    "clock": ("clock", "rosgraph_msgs/msg/Clock"),
    "objects": ("objects/markers", "visualization_msgs/msg/MarkerArray"),
    "detections": ("perception/markers", "visualization_msgs/msg/MarkerArray"),
    "acc": ("acc/status", "std_msgs/msg/Float64MultiArray"),
}


def test_up_ros2_shows_the_loop_to_ros_tools(slipstream_bin, free_port, tmp_path):
    ts = typestore(slipstream_bin)
    endpoint = f"tcp/127.0.0.1:{free_port}"
    up = subprocess.Popen(
        [slipstream_bin, "-l", endpoint, "up", "--ros2", "--scenario", "cut-in", "--duration", "40", "--plain",
         "--report", str(tmp_path / "report")],
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, cwd=ROOT)
    try:
        # Discovery as `ros2 topic list -t` does it: from the liveliness tokens only.
        def listed():
            topics = dict(sdk_discovery.get_topic_names_and_types(domain_id=0, router_port=free_port, timeout=1.0))
            return topics if "/camera/front/camera_info" in topics else None
        assert wait_for(listed, up, 60), "the ROS graph never showed the bridge's topics"
        topics = listed()
        for name, type_name in ROUTES.values():
            assert topics.get("/" + name) == [type_name], (name, topics)
        info = sdk_discovery.get_topic_info("/camera/front/camera_info", domain_id=0, router_port=free_port,
                                            verbose=True, timeout=1.0)
        assert info.publishers[0].node_name == "slipstream"
        assert info.publishers[0].qos.startswith(":1:"), "camera info is reliable and transient local"

        col = Collector()
        with zenoh.open(peer_config(endpoint)) as session:
            subs = [session.declare_subscriber(f"0/{key}/**", col.handler(name, ros_decoder(ts, type_name)))
                    for name, (key, type_name) in ROUTES.items()]
            subs.append(session.declare_subscriber(
                "camera/front", col.handler("frame", lambda s: decode(s.payload.to_bytes()))))
            # A late subscriber still gets the camera info: the publisher keeps it in its cache.
            late = zenoh.ext.declare_advanced_subscriber(
                session, "0/camera/front/camera_info/**",
                col.handler("info", ros_decoder(ts, "sensor_msgs/msg/CameraInfo")),
                history=zenoh.ext.HistoryConfig(detect_late_publishers=True))
            assert wait_for(lambda: all(col.count(n) >= 5 for n in list(ROUTES) + ["frame"]) and col.count("info"),
                            up, 60), {n: col.count(n) for n in list(ROUTES) + ["frame", "info"]}
            time.sleep(1.0)
            late.undeclare()
            for s in subs:
                s.undeclare()
        check_messages(col)
    finally:
        up.send_signal(signal.SIGINT)  # as Ctrl-C: up stops its nodes
        up.wait(timeout=60)


def check_messages(col):
    images = col.items("image")
    img, att = images[-1]
    assert (img.width, img.height, img.encoding, img.step) == (640, 480, "rgb8", 640 * 3)
    assert len(img.data) == 640 * 480 * 3
    assert len(att.gid) == 16
    seqs = [a.sequence_id for _, a in images]
    assert all(x < y for x, y in zip(seqs, seqs[1:])), "rmw_zenoh sequence numbers rise"
    # The same frame, by simulation time: the same pixels.
    frames = {h["stamp_sim_ns"]: body for _, h, body in col.items("frame")}
    matched = 0
    for img, _ in images:
        stamp = img.header.stamp.sec * 1_000_000_000 + img.header.stamp.nanosec
        if stamp in frames:
            assert bytes(img.data) == bytes(frames[stamp]["data"])
            matched += 1
    assert matched >= 1, "no ROS image matched a slipstream frame by stamp"
    info, _ = col.items("info")[-1]
    assert info.k[0] > 0 and info.k[8] == 1.0 and info.width == 640
    assert info.header.frame_id == "camera_front_optical"
    odo, _ = col.items("odometry")[-1]
    assert odo.header.frame_id == "world" and odo.child_frame_id == "ego"
    assert 5.0 < odo.twist.twist.linear.x < 40.0
    tf, _ = col.items("tf")[-1]
    assert tf.transforms[0].child_frame_id == "ego"
    clocks = [c.clock.sec + c.clock.nanosec / 1e9 for c, _ in col.items("clock")]
    assert all(a <= b for a, b in zip(clocks, clocks[1:])) and clocks[-1] > 0
    markers, _ = col.items("objects")[-1]
    assert markers.markers[0].action == 3, "each array starts by clearing the last"
    assert any(m.type == 1 and m.scale.x > 1.0 for m in markers.markers[1:])
    acc, _ = col.items("acc")[-1]
    assert acc.layout.dim[0].label.split(",")[0] == "mode" and len(acc.data) == acc.layout.dim[0].size


class Controller:
    """A ROS 2 controller stand-in: AckermannDriveStamped in CDR by rosbags, on the key and with
    the attachment zenoh-ros2-sdk makes for a ROS 2 publisher (its own gid)."""

    TYPE = "ackermann_msgs/msg/AckermannDriveStamped"

    def __init__(self, session, ts, gid):
        dds = "ackermann_msgs::msg::dds_::AckermannDriveStamped_"
        self.key = topic_keyexpr(0, "/vehicle/ackermann_cmd", dds, ts.hash_rihs01(self.TYPE))
        self.pub = session.declare_publisher(self.key)
        self.ts, self.gid, self.seq = ts, gid, 0
        self.types = ts.types

    def send(self, speed, steering=0.0, acceleration=0.0):
        Time = self.types["builtin_interfaces/msg/Time"]
        Header = self.types["std_msgs/msg/Header"]
        Drive = self.types["ackermann_msgs/msg/AckermannDrive"]
        Stamped = self.types[self.TYPE]
        msg = Stamped(header=Header(stamp=Time(sec=0, nanosec=0), frame_id="ego"),
                      drive=Drive(steering_angle=steering, steering_angle_velocity=0.0, speed=speed,
                                  acceleration=acceleration, jerk=0.0))
        self.seq += 1
        att = Attachment(sequence_id=self.seq, timestamp_ns=time.time_ns(), gid=self.gid)
        self.pub.put(bytes(self.ts.serialize_cdr(msg, self.TYPE)), attachment=att.to_bytes())


def test_a_ros_controller_drives_the_ego_and_bad_commands_are_refused(slipstream_bin, sim_bin, free_port):
    ts = typestore(slipstream_bin)
    endpoint = f"tcp/127.0.0.1:{free_port}"
    sim = subprocess.Popen([sim_bin, "--scenario", "open-road", "--mode", "realtime", "--duration", "60",
                            "-l", endpoint], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, cwd=ROOT)
    bridge = subprocess.Popen([slipstream_bin, "-e", endpoint, "ros2", "--control", "--json", "--duration", "25"],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT)
    try:
        speeds = Collector(keep=100000)
        with zenoh.open(peer_config(endpoint)) as session:
            sub = session.declare_subscriber(
                "vehicle/state", speeds.handler("state", lambda s: decode(s.payload.to_bytes())[2]))
            assert wait_for(lambda: speeds.count("state") > 10, bridge, 30), "no vehicle/state"
            time.sleep(2.0)  # the bridge's command subscription is declared
            ctl = Controller(session, ts, b"\x01" * 16)
            stranger = Controller(session, ts, b"\x02" * 16)
            start = speeds.items("state")[-1]["speed_mps"]
            for i in range(80):  # 8 s at 10 Hz toward 8 m/s, with bad commands in between
                ctl.send(8.0)
                if i % 20 == 5:
                    ctl.send(float("nan"))
                    ctl.send(-5.0)
                    stranger.send(35.0)
                time.sleep(0.1)
            driven = speeds.items("state")[-1]
            # The controller stops (dies): the loop goes on, the simulator's watchdog brakes.
            n_before = speeds.count("state")
            time.sleep(2.0)
            after = speeds.items("state")[-1]
            assert speeds.count("state") > n_before, "the simulator kept running"
            sub.undeclare()
        assert start > 15.0
        assert 5.0 < driven["speed_mps"] < 12.0, (start, driven["speed_mps"])
        assert after["applied"]["brake"] > 0.0 and after["applied"]["throttle"] == 0.0, after["applied"]
        out, err = bridge.communicate(timeout=60)
        face = json.loads(out)
        routes = {r["route"]: r for r in face["routes"]}
        # Nobody subscribed to the images: not converted at all. Latched routes fill their cache.
        assert routes["camera_front"]["sent"] == 0 and routes["camera_front"]["dropped"] == 0, routes
        assert routes["camera_front_info"]["sent"] >= 1 and routes["tf_static"]["sent"] >= 1, routes
        stats = face["commands"]
        assert stats["accepted"] >= 70, stats
        assert stats["refused"] == 12, stats  # 4 rounds of NaN, negative speed, second publisher
        assert stats["applied"] > 100, stats
    finally:
        for p in (bridge, sim):
            if p.poll() is None:
                p.send_signal(signal.SIGINT)
                p.wait(timeout=30)


def read_ros2_bag(path):
    """Every message of a ros2-profile MCAP file decoded by mcap-ros2-support; per topic the
    decoded messages, and the file's profile and encodings."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    per_topic, encodings = {}, set()
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        profile = reader.get_header().profile
        for schema, channel, message, decoded in reader.iter_decoded_messages():
            encodings.add((schema.encoding, channel.message_encoding))
            per_topic.setdefault(channel.topic, []).append((message, decoded))
    return profile, encodings, per_topic


def test_ros2_recordings_and_conversions_decode_with_mcap_ros2_support(slipstream_bin, free_port, tmp_path):
    report = tmp_path / "report"
    up = subprocess.run(
        [slipstream_bin, "-l", f"tcp/127.0.0.1:{free_port}", "up", "--ros2", "--record", "--mode", "lockstep",
         "--scenario", "cut-in", "--duration", "3", "--plain", "--report", str(report)],
        capture_output=True, text=True, cwd=ROOT, timeout=300)
    assert up.returncode == 0, up.stderr[-2000:]
    converted = tmp_path / "converted.mcap"
    conv = subprocess.run([slipstream_bin, "convert", str(report / "run.mcap"), "--to", "ros2", str(converted)],
                          capture_output=True, text=True, cwd=ROOT, timeout=300)
    assert conv.returncode == 0, conv.stdout + conv.stderr
    live = read_ros2_bag(report / "run.ros2.mcap")
    conv_bag = read_ros2_bag(converted)
    for profile, encodings, per_topic in (live, conv_bag):
        assert profile == "ros2"
        assert encodings == {("ros2msg", "cdr")}
        for topic in ("/camera/front/image_raw", "/camera/front/camera_info", "/vehicle/odometry", "/tf",
                      "/tf_static", "/clock", "/objects/markers", "/acc/status"):
            assert per_topic.get(topic), (topic, sorted(per_topic))
        img = per_topic["/camera/front/image_raw"][-1][1]
        assert (img.width, img.height, img.encoding, len(img.data)) == (640, 480, "rgb8", 640 * 480 * 3)
        static = per_topic["/tf_static"][-1][1]
        assert {t.child_frame_id for t in static.transforms} >= {"camera_front", "camera_front_optical"}
    # The conversion holds every clock tick the run recorded; the live bag the same ticks, as
    # many as it took in the time.
    clock = lambda bag: [m.clock.sec * 10**9 + m.clock.nanosec for _, m in bag[2]["/clock"]]  # noqa: E731
    assert set(clock(live)) <= set(clock(conv_bag))
    assert len(clock(conv_bag)) >= 290, "3 s of 100 Hz clock"
    # Log time is when a message was taken, publish time the bus publisher's stamp.
    msg, _ = conv_bag[2]["/clock"][-1]
    assert msg.log_time >= msg.publish_time > 0


def test_a_ros_host_on_another_subnet_sees_the_loop_through_the_router(slipstream_bin, sim_bin, tmp_path):
    from netns import Lan, can_create_namespaces

    why = can_create_namespaces()
    if why:
        pytest.skip(f"namespace test: {why}")
    lan = Lan(["router", "sim", "ros"])
    procs = []
    try:
        router = f"tcp/{lan.addr['router']}:7447"
        client = ["-c", "config/client.json5", "-e", router, "--cfg", "transport/shared_memory/enabled:false"]
        logs = {n: open(tmp_path / f"{n}.log", "w") for n in ("router", "sim", "bridge")}
        procs.append(lan.popen("router", [slipstream_bin, "router", "-c", "config/router.json5"], cwd=ROOT,
                               stdout=logs["router"], stderr=subprocess.STDOUT))
        procs.append(lan.popen("sim", [sim_bin, "--scenario", "steady-follow", "--duration", "120", *client],
                               cwd=ROOT, stdout=logs["sim"], stderr=subprocess.STDOUT))
        procs.append(lan.popen("sim", [slipstream_bin, *client, "ros2"], cwd=ROOT, stdout=logs["bridge"],
                               stderr=subprocess.STDOUT))
        remote = lan.popen("ros", [sys.executable, str(ROOT / "tests" / "python" / "ros2_remote.py"),
                                   lan.addr["router"], "7447", "45"], cwd=ROOT, stdout=subprocess.PIPE, text=True)
        out, _ = remote.communicate(timeout=90)
        seen = json.loads(out)
    finally:
        for p in procs:
            p.send_signal(signal.SIGINT)
        for p in procs:
            try:
                p.wait(timeout=20)
            except subprocess.TimeoutExpired:
                p.kill()
        lan.close()
    tails = "\n".join(f"--- {f.name}\n{f.read_text()[-1500:]}" for f in sorted(tmp_path.glob("*.log")))
    assert seen["topics"].get("/vehicle/odometry") == ["nav_msgs/msg/Odometry"], (seen, tails)
    assert seen["topics"].get("/camera/front/image_raw") == ["sensor_msgs/msg/Image"], seen
    assert seen["clock"] >= 50 and seen["odometry"] >= 50, (seen, tails)
    assert 10.0 < seen["speed"] < 40.0, seen


def test_the_domain_and_distribution_choose_the_keys(slipstream_bin):
    import os

    def mapping(*flags, domain=None):
        env = dict(os.environ)
        env.pop("ROS_DOMAIN_ID", None)
        if domain is not None:
            env["ROS_DOMAIN_ID"] = domain
        return subprocess.run([slipstream_bin, "ros2", "--list", "--json", *flags], capture_output=True, text=True,
                              cwd=ROOT, env=env)

    rows = {r["route"]: r for r in json.loads(mapping(domain="7").stdout)}
    assert rows["clock"]["key"].startswith("7/clock/rosgraph_msgs::msg::dds_::Clock_/RIHS01_")
    humble = {r["route"]: r for r in json.loads(mapping("--distro", "humble", "--domain-id", "3", domain="7").stdout)}
    assert humble["clock"]["key"] == "3/clock/rosgraph_msgs::msg::dds_::Clock_/TypeHashNotSupported"
    assert humble["command"]["enabled"] is False
    bad = mapping(domain="lots")
    assert bad.returncode != 0 and "ROS_DOMAIN_ID" in bad.stderr and "0 to 232" in bad.stderr, bad.stderr
