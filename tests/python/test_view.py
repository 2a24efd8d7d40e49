"""The live view seen by an independent Foxglove WebSocket client (the `websockets` package,
subprotocol foxglove.sdk.v1): `slipstream up --view` advertises its channels and sends camera
images, annotations with boxes, scene updates and the ACC's series; a taken port is a clear
error (docs/viewing.md)."""

import json
import signal
import socket
import struct
import subprocess
import time

import pytest
from conftest import ROOT, reserve_port

ws_sync = pytest.importorskip("websockets.sync.client", reason="scripts/test.sh installs the websockets package")

SUBPROTOCOL = "foxglove.sdk.v1"
OP_MESSAGE_DATA = 0x01
WANTED = ("/camera/front", "/camera/front/annotations", "/camera/front/calibration", "/scene/vehicles",
          "/scene/road", "/tf", "/acc")
LAYOUT = ROOT / "config" / "foxglove-layout.json"


def layout_references():
    """(topics, {topic: fields}) that config/foxglove-layout.json's panels show."""
    topics, fields = set(), {}
    for panel in json.loads(LAYOUT.read_text())["configById"].values():
        image = panel.get("imageMode", {})
        topics.update(t for t in (image.get("imageTopic"), image.get("calibrationTopic")) if t)
        topics.update(image.get("annotations", {}))
        topics.update(panel.get("topics", {}))
        for path in [p["value"] for p in panel.get("paths", [])] + [panel.get("topicPath", "")]:
            if path:
                topic, _, field = path.partition(".")
                topics.add(topic)
                if field:
                    fields.setdefault(topic, set()).add(field)
    return topics, fields


def test_the_layouts_panels_use_the_current_title_key():
    """Foxglove names a panel by `foxglovePanelTitle`; a Plot's `title` is the legacy key."""
    panels = json.loads(LAYOUT.read_text())["configById"]
    plots = {k: v for k, v in panels.items() if k.startswith("Plot!")}
    assert plots, "the layout has no Plot panel"
    for name, config in plots.items():
        assert "title" not in config, f"{name} uses the legacy key `title`"
        assert config.get("foxglovePanelTitle"), f"{name} has no foxglovePanelTitle"


def protobuf_fields(data):
    """Top-level fields of a protobuf message: {tag: [values]} (ints for varint/fixed, bytes
    for length-delimited). Enough to check Foxglove's schemas without their generated code."""
    fields, i = {}, 0
    while i < len(data):
        key, i = varint(data, i)
        tag, wire = key >> 3, key & 7
        if wire == 0:
            value, i = varint(data, i)
        elif wire == 1:
            value, i = struct.unpack_from("<Q", data, i)[0], i + 8
        elif wire == 2:
            n, i = varint(data, i)
            value, i = bytes(data[i:i + n]), i + n
        elif wire == 5:
            value, i = struct.unpack_from("<I", data, i)[0], i + 4
        else:
            raise ValueError(f"wire type {wire} at {i}")
        fields.setdefault(tag, []).append(value)
    return fields


def varint(data, i):
    value, shift = 0, 0
    while True:
        b = data[i]
        i += 1
        value |= (b & 0x7F) << shift
        shift += 7
        if not b & 0x80:
            return value, i


def wait_for_port(port, proc, timeout):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        assert proc.poll() is None, proc.stderr.read() if proc.stderr else "up ended"
        with socket.socket() as s:
            if s.connect_ex(("127.0.0.1", port)) == 0:
                return
        time.sleep(0.2)
    raise AssertionError(f"nothing listens on {port} after {timeout} s")


def watch(port, deadline):
    """Connects, subscribes to the wanted channels as they are advertised, and collects their
    messages until each has one worth checking (or the deadline). Returns (advertised, got)."""
    advertised, subscribed, got = {}, {}, {t: [] for t in WANTED}
    with ws_sync.connect(f"ws://127.0.0.1:{port}", subprotocols=[SUBPROTOCOL], max_size=None,
                         open_timeout=30) as ws:
        assert ws.subprotocol == SUBPROTOCOL
        while time.monotonic() < deadline and not all(ready(t, got[t]) for t in WANTED):
            try:
                frame = ws.recv(timeout=max(0.1, deadline - time.monotonic()))
            except TimeoutError:
                break
            if isinstance(frame, str):
                msg = json.loads(frame)
                if msg.get("op") == "advertise":
                    new = []
                    for ch in msg["channels"]:
                        advertised[ch["topic"]] = ch
                        if ch["topic"] in WANTED and ch["topic"] not in subscribed.values():
                            sub = len(subscribed) + 1
                            subscribed[sub] = ch["topic"]
                            new.append({"id": sub, "channelId": ch["id"]})
                    if new:
                        ws.send(json.dumps({"op": "subscribe", "subscriptions": new}))
            elif frame[0] == OP_MESSAGE_DATA:
                sub, log_time = struct.unpack_from("<IQ", frame, 1)
                got[subscribed[sub]].append((log_time, frame[13:]))
    return advertised, got


def ready(topic, messages):
    if topic == "/camera/front/annotations":
        return any(2 in protobuf_fields(m) for _, m in messages)  # at least one box
    return bool(messages)


def test_up_view_serves_camera_boxes_scene_and_series(slipstream_bin, free_port, tmp_path):
    view_port = reserve_port()
    report = tmp_path / "report"
    up = subprocess.Popen(
        [slipstream_bin, "-l", f"tcp/127.0.0.1:{free_port}", "up", "--scenario", "cut-in", "--duration", "40",
         "--view", "--view-port", str(view_port), "--plain", "--report", str(report)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT)
    try:
        wait_for_port(view_port, up, 60)
        advertised, got = watch(view_port, time.monotonic() + 90)
    finally:
        up.send_signal(signal.SIGINT)
        out, err = up.communicate(timeout=60)

    for topic in WANTED:
        assert topic in advertised, (topic, sorted(advertised))
        assert got[topic], (topic, {t: len(m) for t, m in got.items()}, err[-2000:])
    assert advertised["/camera/front"]["schemaName"] == "foxglove.RawImage"
    assert advertised["/camera/front"]["encoding"] == "protobuf"
    assert advertised["/camera/front/annotations"]["schemaName"] == "foxglove.ImageAnnotations"
    assert advertised["/scene/vehicles"]["schemaName"] == "foxglove.SceneUpdate"
    assert advertised["/acc"]["encoding"] == "json"

    # An image: the whole frame, its pixels not blank.
    image = protobuf_fields(got["/camera/front"][-1][1])
    width, height = image[2][0], image[3][0]
    assert (width, height) == (640, 480), image.keys()
    assert image[4] == [b"rgb8"] and image[5] == [width * 3]
    pixels = image[6][0]
    assert len(pixels) == width * height * 3
    assert len(set(pixels[::997])) > 8, "a rendered road scene has more than a few colours"

    # Boxes: closed outlines of four points each.
    boxes = [protobuf_fields(p) for _, m in got["/camera/front/annotations"] for p in protobuf_fields(m).get(2, [])]
    assert boxes and all(len(b[3]) == 4 for b in boxes), boxes[:2]

    # The scene: the ego and the vehicles as cube entities.
    scene = protobuf_fields(got["/scene/vehicles"][-1][1])
    ids = [protobuf_fields(e)[3][0].decode() for e in scene[2]]
    assert "ego" in ids and any(i.startswith("vehicle/") for i in ids), ids

    series = json.loads(got["/acc"][-1][1])
    assert series["speed_mps"] > 0 and "gap_m" in series and "mode" in series, series

    # The layout shipped for the Foxglove app shows only what the view serves.
    topics, fields = layout_references()
    assert topics <= set(advertised), topics - set(advertised)
    assert fields["/acc"] <= set(series), fields["/acc"] - set(series)
    calibration = protobuf_fields(got["/camera/front/calibration"][-1][1])
    assert (calibration[2][0], calibration[3][0]) == (640, 480)

    # Per channel the log times go forward.
    for topic, messages in got.items():
        times = [t for t, _ in messages]
        assert times == sorted(times), topic

    stats = json.loads((report / "report.json").read_text())["view"]
    assert stats["images"] >= len(got["/camera/front"]) > 0, stats
    assert "live view on http://localhost:" in err and f"ws://localhost:{view_port}" in err, err[-2000:]
    assert up.returncode in (0, 130), (up.returncode, err[-2000:])


def test_a_taken_port_is_a_clear_error(slipstream_bin, free_port):
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        run = subprocess.run(
            [slipstream_bin, "-l", f"tcp/127.0.0.1:{free_port}", "view", "--view-port", str(port), "--duration", "1"],
            capture_output=True, text=True, timeout=60, cwd=ROOT)
    assert run.returncode == 1, (run.returncode, run.stderr)
    assert f"cannot serve the live view on 127.0.0.1:{port}" in run.stderr, run.stderr
    assert "--view-port" in run.stderr


def test_a_client_offering_only_the_old_subprotocol_gets_in_under_its_name(slipstream_bin, free_port):
    """docs/viewing.md: viewers built on @foxglove/ws-protocol (Lichtblick) offer only
    foxglove.websocket.v1, which the Foxglove SDK's server alone refuses; through the view's
    port they get in, are answered with the name they offered and get the server's info and
    channels as a foxglove.sdk.v1 client does."""
    port = reserve_port()
    view = subprocess.Popen(
        [slipstream_bin, "-l", f"tcp/127.0.0.1:{free_port}", "view", "--view-port", str(port), "--duration", "30"],
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, cwd=ROOT)
    try:
        wait_for_port(port, view, 20)
        for offered in (["foxglove.websocket.v1"], ["foxglove.websocket.v1", SUBPROTOCOL]):
            with ws_sync.connect(f"ws://127.0.0.1:{port}", subprotocols=offered, open_timeout=5) as ws:
                assert ws.subprotocol == offered[-1], (offered, ws.subprotocol)
                ops = {json.loads(ws.recv(timeout=5))["op"] for _ in range(2)}
                assert ops == {"serverInfo", "advertise"}, (offered, ops)
    finally:
        view.send_signal(signal.SIGINT)
        view.wait(timeout=30)
