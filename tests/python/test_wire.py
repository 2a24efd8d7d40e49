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
    assert len(examples) == 12
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
    assert state_lane[:5] == bytes([WIRE_VERSION, 1, 1, 0, 5]) and WIRE_VERSION == 4
    event = encode("SimEvent", header, {"kind": {"variant": "ControlTimeout", "late": ["acc"]}})
    assert event[5:] == bytes([3, 1, 3]) + b"acc"
    assert decode(event)[2]["kind"]["late"] == ["acc"]


def test_bad_payloads_are_all_counted_and_printed_rate_limited(capsys):
    from slipstream_client import BadPayloads

    bad = BadPayloads()
    for i in range(150):
        bad("vehicle/speed", WireError(f"bad {i}"))
    lines = capsys.readouterr().out.splitlines()
    assert bad.count == 150
    assert lines == [f"# vehicle/speed: undecodable payload #{n}: bad {n - 1}" for n in (1, 10, 100)]
