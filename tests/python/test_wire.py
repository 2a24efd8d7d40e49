"""The Python codec, written from docs/wire-format.md, against the Rust encoder's examples."""

import json
import subprocess

import pytest

from slipstream_client import WireError, decode, encode
from slipstream_client.wire import WIRE_VERSION


@pytest.fixture(scope="module")
def examples(slipstream_bin):
    out = subprocess.run([slipstream_bin, "wire-examples"], check=True, capture_output=True, text=True, timeout=60).stdout
    return {e["kind"]: bytes.fromhex(e["hex"].replace(" ", "")) for e in json.loads(out)}


def test_every_rust_example_decodes_and_reencodes_byte_for_byte(examples):
    assert len(examples) == 13
    for kind, payload in examples.items():
        got_kind, header, body = decode(payload)
        assert got_kind == kind
        assert header == {"seq": 7, "stamp_sim_ns": 1_250_000_000, "stamp_pub_ns": 1_700_000_000_123_456_789}
        assert encode(kind, header, body) == payload, kind


def test_decoded_values_are_the_documented_ones(examples):
    assert decode(examples["Speed"])[2] == {"speed_mps": 27.5}
    assert decode(examples["RoadMap"])[2] == {
        "lanes": 3, "lane_width_m": 3.5, "length_m": 4000.0,
        "curves": [{"start_m": 300.0, "length_m": 350.0, "radius_m": 600.0}],
        "lane_ends": [{"lane": 0, "end_m": 900.0, "taper_m": 120.0}]}
    control = decode(examples["ControlCommand"])[2]
    assert control == {"throttle": 0.25, "brake": 0.0, "steer": -0.5, "answers_step": 125,
                       "perception_stamp_pub_ns": 1_700_000_000_100_000_000}
    frame = decode(examples["CameraFrame"])[2]
    assert (frame["width"], frame["height"], frame["encoding"]) == (2, 1, "Rgb8")
    assert frame["data"] == bytes([255, 0, 0, 0, 128, 255])
    gt = decode(examples["GroundTruthObjects"])[2]
    car = gt["objects"][0]
    assert (car["id"], car["class"], car["lane"]) == (3, "Car", 1)
    assert car["position_in_ego_m"] == [27.75, 0.0, 0.0]
    assert car["bbox"]["u_max_px"] == 340.0 and car["brake_lights"] is True
    detection = decode(examples["Detections"])[2]["detections"][0]
    assert (detection["relative_speed_mps"], detection["brake_lights"]) == (-2.5, True)
    assert (detection["distance_sigma_m"], detection["relative_speed_sigma_mps"]) == (0.25, 0.5)
    state = decode(examples["VehicleState"])[2]
    assert state["position_in_world_m"] == [31.25, -1.75, 0.0] and state["applied"]["answers_step"] == 124
    assert decode(examples["SimEvent"])[2]["kind"] == {"variant": "Collision", "other_id": 3, "relative_speed_mps": 4.5}
    status = decode(examples["AccStatus"])[2]
    assert status["mode"] == "Follow" and status["lead"]["ttc_s"] == 11.1 and status["warnings"] == []
    assert decode(examples["AccCommand"])[2] == {"enable": True, "set_speed_mps": 25.0, "time_gap_s": None}
    ego = decode(examples["EgoInfo"])[2]
    assert (ego["class"], ego["size_m"], ego["rear_overhang_m"]) == ("Car", [4.6, 1.85, 1.45], 0.95)
    assert (ego["mass_kg"], ego["set_speed_mps"], ego["time_gap_s"]) == (1500.0, 25.0, 1.8)


def test_strict_decoding(examples):
    for kind, payload in examples.items():
        for cut in range(len(payload)):
            with pytest.raises(WireError):
                decode(payload[:cut])
        with pytest.raises(WireError, match="trailing"):
            decode(payload + b"\x00")
    speed = examples["Speed"]
    with pytest.raises(WireError, match="version"):
        decode(b"\x01" + speed[1:])
    with pytest.raises(WireError, match="expected ControlCommand"):
        decode(speed, expected="ControlCommand")


def test_python_encodes_what_rust_documents():
    header = {"seq": 1, "stamp_sim_ns": 0, "stamp_pub_ns": 5}
    # -1 as i32 is zigzag 1; 300 as varint is ac 02.
    state_lane = encode("Speed", header, {"speed_mps": 1.0})
    assert state_lane[:5] == bytes([WIRE_VERSION, 1, 1, 0, 5]) and WIRE_VERSION == 5
    event = encode("SimEvent", header, {"kind": {"variant": "ControlTimeout", "late": ["acc"]}})
    assert event[5:] == bytes([3, 1, 3]) + b"acc"
    assert decode(event)[2]["kind"]["late"] == ["acc"]


def test_bad_payloads_are_all_counted_and_logged_rate_limited(caplog, capsys):
    from slipstream_client import BadPayloads

    bad = BadPayloads()
    with caplog.at_level("WARNING", logger="slipstream_client"):
        for i in range(150):
            bad("vehicle/speed", WireError(f"bad {i}"))
    assert bad.count == 150
    assert caplog.messages == [f"vehicle/speed: undecodable payload #{n}: bad {n - 1}" for n in (1, 10, 100)]
    assert capsys.readouterr().out == ""  # a library prints nothing of its own


def _varint(n):
    out = bytearray()
    while True:
        b, n = n & 0x7F, n >> 7
        out.append(b | (0x80 if n else 0))
        if not n:
            return bytes(out)


def _edge_cases(examples):
    """(name, payload, accepted per docs/wire-format.md) at the edges the doc states."""
    h = {"seq": 7, "stamp_sim_ns": 1_250_000_000, "stamp_pub_ns": 1_700_000_000_123_456_789}
    head = lambda kind: bytes([WIRE_VERSION, {"Speed": 1, "SimClock": 8}[kind]])
    tail = encode("Speed", h, {"speed_mps": 1.0})[2 + len(_varint(7)):]  # after header.seq
    clock = decode(examples["SimClock"])[2]
    clock_body = encode("SimClock", h, clock)
    mode_at = len(clock_body) - 8 - 1  # the mode's index sits before physics_hz (f64)
    control = decode(examples["ControlCommand"])[2]
    detections = decode(examples["Detections"])[2]
    info = decode(examples["CameraInfo"])[2]
    road = decode(examples["RoadMap"])[2]
    command = decode(examples["AccCommand"])[2]
    ego = decode(examples["EgoInfo"])[2]
    det = lambda **f: {**detections, "detections": [{**detections["detections"][0], **f}]}
    nan, inf = float("nan"), float("inf")
    return [
        ("seq non-minimal", head("Speed") + b"\x87\x00" + tail, True),
        ("seq 10 bytes, last 01", head("Speed") + b"\xff" * 9 + b"\x01" + tail, True),
        ("seq overflowing u64", head("Speed") + b"\xff" * 9 + b"\x02" + tail, False),
        ("seq 11 bytes", head("Speed") + b"\x80" * 10 + b"\x00" + tail, False),
        ("enum index non-minimal", clock_body[:mode_at] + b"\x80\x80\x80\x80\x00" + clock_body[mode_at + 1:], True),
        ("enum index overflowing u32", clock_body[:mode_at] + b"\xff\xff\xff\xff\x1f" + clock_body[mode_at + 1:], False),
        ("enum index past the variants", clock_body[:mode_at] + b"\x03" + clock_body[mode_at + 1:], False),
        ("throttle 1 (range end)", encode("ControlCommand", h, {**control, "throttle": 1.0}), True),
        ("steer -1 (range end)", encode("ControlCommand", h, {**control, "steer": -1.0}), True),
        ("throttle NaN", encode("ControlCommand", h, {**control, "throttle": nan}), False),
        ("brake infinite", encode("ControlCommand", h, {**control, "brake": inf}), False),
        ("throttle just above 1", encode("ControlCommand", h, {**control, "throttle": 1.0000001}), False),
        ("confidence NaN", encode("Detections", h, det(confidence=nan)), False),
        ("confidence 0", encode("Detections", h, det(confidence=0.0)), True),
        ("sigma infinite", encode("Detections", h, det(distance_sigma_m=inf)), True),
        ("sigma negative", encode("Detections", h, det(relative_speed_sigma_mps=-1e-9)), False),
        ("focal length 0", encode("CameraInfo", h, {**info, "fx_px": 0.0}), False),
        ("focal length NaN", encode("CameraInfo", h, {**info, "fy_px": nan}), False),
        ("focal length infinite", encode("CameraInfo", h, {**info, "fx_px": inf}), True),
        ("cx NaN (no rule)", encode("CameraInfo", h, {**info, "cx_px": nan}), True),
        ("set speed negative", encode("AccCommand", h, {**command, "set_speed_mps": -1.0}), False),
        ("set speed infinite", encode("AccCommand", h, {**command, "set_speed_mps": inf}), False),
        ("time gap 0", encode("AccCommand", h, {**command, "time_gap_s": 0.0}), False),
        ("9 lanes", encode("RoadMap", h, {**road, "lanes": 9}), False),
        ("lane width 6 (range end)", encode("RoadMap", h, {**road, "lane_width_m": 6.0}), True),
        ("lane width NaN", encode("RoadMap", h, {**road, "lane_width_m": nan}), False),
        ("curve radius 29", encode("RoadMap", h, {**road, "curves": [{**road["curves"][0], "radius_m": -29.0}]}), False),
        ("lane end past the road", encode("RoadMap", h, {**road, "lane_ends": [{**road["lane_ends"][0], "end_m": 5000.0}]}), False),
        ("ego mass 0", encode("EgoInfo", h, {**ego, "mass_kg": 0.0}), False),
        ("ego height NaN", encode("EgoInfo", h, {**ego, "size_m": [4.6, 1.85, nan]}), False),
        ("ego set speed 0", encode("EgoInfo", h, {**ego, "set_speed_mps": 0.0}), True),
        ("ego time gap negative", encode("EgoInfo", h, {**ego, "time_gap_s": -1.0}), False),
        ("ego no time gap", encode("EgoInfo", h, {**ego, "time_gap_s": None}), True),
        ("speed NaN (no rule)", encode("Speed", h, {"speed_mps": nan}), True),
        ("option tag 2", encode("AccCommand", h, command)[:-1] + b"\x02", False),
        ("length past the end", encode("SimEvent", h, {"kind": {"variant": "ControlTimeout", "late": ["acc"]}})[:-4] + b"\x09acc", False),
    ]


def test_python_and_rust_agree_at_every_edge_the_doc_states(slipstream_bin, examples):
    cases = _edge_cases(examples)
    hexes = "\n".join(payload.hex() for _, payload, _ in cases) + "\n"
    out = subprocess.run([slipstream_bin, "wire-check"], input=hexes, capture_output=True, text=True, check=True,
                         timeout=60).stdout.splitlines()
    assert len(out) == len(cases)
    for (name, payload, accepted), line in zip(cases, out):
        rust = json.loads(line)
        try:
            decode(payload)
            python = True
        except WireError:
            python = False
        assert ("kind" in rust) == accepted, f"{name}: Rust says {rust}, the doc says accepted={accepted}"
        assert python == accepted, f"{name}: Python says accepted={python}, the doc says {accepted}"


def test_a_late_plain_subscriber_gets_a_latched_topic_by_a_query_as_documented(sim_bin, free_port):
    """docs/wire-format.md "Keys": camera/front/info is published once, when the simulator
    starts; a plain subscriber that starts later never gets it, and a plain query on
    `camera/front/info/@adv/**` (any language, no zenoh-ext) returns it from the cache."""
    import threading
    import time

    import zenoh
    from conftest import peer_config

    endpoint = f"tcp/127.0.0.1:{free_port}"
    sim = subprocess.Popen([sim_bin, "-l", endpoint, "--mode", "realtime", "--duration", "60"],
                           stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        with zenoh.open(peer_config(endpoint)) as session:
            live, lock = [], threading.Lock()
            # The simulator is running (its speed arrives) before anything asks for the info.
            seen = threading.Event()
            speed = session.declare_subscriber("vehicle/speed", lambda s: seen.set())
            assert seen.wait(30), "the simulator never published"

            def on_info(sample):
                with lock:
                    live.append(sample)

            sub = session.declare_subscriber("camera/front/info", on_info)
            time.sleep(1.0)
            with lock:
                assert live == [], "a plain subscriber got a message published before it started"
            replies = session.get("camera/front/info/@adv/**", timeout=5, accept_replies=zenoh.ReplyKeyExpr.ANY)
            cached = [r.ok for r in replies if r.ok is not None]
            assert len(cached) == 1, cached
            assert str(cached[0].key_expr) == "camera/front/info"
            kind, _, info = decode(cached[0].payload.to_bytes())
            assert kind == "CameraInfo" and (info["width"], info["height"]) == (640, 480)
            sub.undeclare()
            speed.undeclare()
    finally:
        sim.kill()
        sim.wait(timeout=10)
