"""The view's page in a real browser: headless Chromium driven by Selenium (Debian's chromium and
chromium-driver, installed by scripts/test.sh) against `slipstream up --view` in lockstep.

The page loads with no console error; the camera panel's pixels are those of the camera topic's
frame it names (downscaled: compared with OpenCV's resize of the frame read from the bus); the
boxes drawn are where perception/objects says for that frame; the plots hold the run's samples
(the same speeds as vehicle/state at the same simulated times). A screenshot of the whole page
goes to target/test-reports/view-page.png (docs/viewing.md shows one). Then the port's bad
input (a path that is not there, bytes that are not HTTP, a client gone mid-request), a
recording in the same page (`view FILE.mcap`: play, pause, the slider), and the page from
another PC (`--view-host 0.0.0.0`, network namespaces)."""

import base64
import json
import os
import pathlib
import signal
import socket
import subprocess
import sys
import threading
import time
import urllib.error
import urllib.request

import numpy as np
import pytest
import zenoh
from conftest import ROOT, peer_config, reserve_port

from slipstream_client import decode
from slipstream_client.image import frame_array

webdriver = pytest.importorskip("selenium.webdriver", reason="scripts/test.sh installs selenium")
cv2 = pytest.importorskip("cv2", reason="scripts/test.sh installs opencv-python-headless")

NAMESPACE = "webpage"
REPORTS = ROOT / "target" / "test-reports"
# What is kept from the bus to match the page's: frames (900 kB each) from the last second or
# so, the small messages from the whole minute the plots show.
KEEP_FRAMES = 150
KEEP_SMALL = 100_000


def chrome():
    REPORTS.mkdir(parents=True, exist_ok=True)
    opts = webdriver.ChromeOptions()
    opts.binary_location = os.environ.get("CHROMIUM", "/usr/bin/chromium")
    for arg in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage",
                "--window-size=1600,1200", "--force-device-scale-factor=1"):
        opts.add_argument(arg)
    opts.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    service = webdriver.ChromeService(executable_path=os.environ.get("CHROMEDRIVER", "/usr/bin/chromedriver"),
                                      log_output=str(REPORTS / "chromedriver.log"))
    return webdriver.Chrome(options=opts, service=service)


class Bus:
    """The loop's frames, detections and states as the bus carries them, newest KEEP."""

    def __init__(self, endpoint):
        self.lock = threading.Lock()
        self.frozen = False
        self.frames, self.detections, self.speeds = {}, {}, {}
        self.session = zenoh.open(peer_config(endpoint))
        self.subs = [self.session.declare_subscriber(f"{NAMESPACE}/{key}", handler) for key, handler in (
            ("camera/front", self.on_frame), ("perception/objects", self.on_objects), ("vehicle/state", self.on_state))]

    def keep(self, table, key, value, limit=KEEP_SMALL):
        with self.lock:
            if self.frozen:
                return
            table[key] = value
            while len(table) > limit:
                del table[next(iter(table))]

    def on_frame(self, sample):
        payload = sample.payload.to_bytes()
        _, header, _ = decode(payload, copy=False)
        self.keep(self.frames, header["stamp_pub_ns"], payload, KEEP_FRAMES)

    def on_objects(self, sample):
        _, _, objects = decode(sample.payload.to_bytes())
        self.keep(self.detections, objects["frame_stamp_pub_ns"], objects["detections"])

    def on_state(self, sample):
        _, header, state = decode(sample.payload.to_bytes())
        self.keep(self.speeds, header["stamp_sim_ns"] // 1_000_000, state["speed_mps"])

    def close(self):
        for s in self.subs:
            s.undeclare()
        self.session.close()


def wait_until(driver, script, timeout, what):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if driver.execute_script(script):
            return
        time.sleep(0.2)
    raise AssertionError(f"the page never {what}: {driver.execute_script('return window.slipstream')}")


def start_up(slipstream_bin, endpoint, view_port):
    return subprocess.Popen(
        [slipstream_bin, "-n", NAMESPACE, "-l", endpoint, "up", "--scenario", "cut-in", "--mode", "lockstep",
         "--duration", "600", "--view", "--view-port", str(view_port), "--plain"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT)


def free_tcp_port():
    return reserve_port()


def canvas_pixels(driver, element_id):
    """The canvas's pixels as an RGBA array, through a lossless PNG."""
    url = driver.execute_script(f"return document.getElementById('{element_id}').toDataURL('image/png')")
    png = np.frombuffer(base64.b64decode(url.split(",", 1)[1]), np.uint8)
    return cv2.cvtColor(cv2.imdecode(png, cv2.IMREAD_UNCHANGED), cv2.COLOR_BGRA2RGBA)


def check_camera(driver, bus, shown):
    frame = bus.frames.get(int(shown["stamp"]))
    assert frame is not None, ("the page shows a frame the bus never carried", shown["stamp"])
    expected = cv2.resize(frame_array(frame)[2], (shown["width"], shown["height"]), interpolation=cv2.INTER_AREA)
    got = canvas_pixels(driver, "front")[:, :, :3]
    assert got.shape == expected.shape, (got.shape, expected.shape)
    diff = np.abs(got.astype(int) - expected.astype(int)).mean()
    upside_down = np.abs(got.astype(int) - expected[::-1].astype(int)).mean()
    # JPEG and another resampling filter: a few levels per pixel; another picture (sky where
    # the road is): tens.
    assert diff < 6, f"mean difference {diff:.1f} per channel from the bus's frame"
    assert upside_down > 4 * diff, (diff, upside_down)


def check_boxes(driver, bus, shown, drawn):
    detections = bus.detections.get(int(shown["stamp"]))
    assert detections, ("no detections for the frame shown", shown["stamp"])
    scale = drawn["scale"]
    assert abs(scale - shown["width"] / shown["frameWidth"]) < 1e-9
    boxes = {b["id"]: b for b in drawn["boxes"] if b["kind"] in ("detection", "lead")}
    assert sorted(boxes) == sorted(d["track_id"] for d in detections), (boxes, detections)
    overlay = canvas_pixels(driver, "front-boxes")
    for d in detections:
        b, bb = boxes[d["track_id"]], d["bbox"]
        for got, want in ((b["x0"], bb["u_min_px"]), (b["y0"], bb["v_min_px"]), (b["x1"], bb["u_max_px"]),
                          (b["y1"], bb["v_max_px"])):
            assert abs(got - want * scale) < 0.01, (b, bb)
        # The outline is painted: the overlay is opaque on the box's left edge.
        x, y = int(round(b["x0"])), int(round((b["y0"] + b["y1"]) / 2))
        x = min(max(x, 0), overlay.shape[1] - 1)
        assert overlay[y, max(x - 1, 0):x + 2, 3].max() > 0, (b, overlay[y, max(x - 1, 0):x + 2])


def check_series(bus, series):
    assert len(series) > 50, len(series)
    matched = [abs(bus.speeds[round(s["t_s"] * 1000)] - s["speed_mps"]) < 1e-4
               for s in series if round(s["t_s"] * 1000) in bus.speeds]
    assert len(matched) > 20 and all(matched), (len(matched), matched.count(False))


def test_the_page_shows_the_loop_in_a_real_browser(slipstream_bin, free_port):
    endpoint, view_port = f"tcp/127.0.0.1:{free_port}", free_tcp_port()
    up = start_up(slipstream_bin, endpoint, view_port)
    bus = driver = None
    try:
        bus = Bus(endpoint)
        driver = chrome()
        url = wait_for_url(up)
        assert url == f"http://localhost:{view_port}", url
        driver.get(url)
        wait_until(driver, "const s = window.slipstream; return s && s.frames >= 5 && s.series.length > 60 && "
                           "s.drawn && s.drawn.boxes.some(b => b.kind !== 'truth')", 120, "showed the loop")
        # Freeze the page, let an update on its way land, stop keeping the bus's messages, then
        # read what the page shows.
        driver.find_element("id", "freeze").click()
        time.sleep(0.3)
        with bus.lock:
            bus.frozen = True
        seen = driver.execute_script("const s = window.slipstream; return {shown: s.shown, drawn: s.drawn, "
                                     "series: s.series, updates: s.updates}")
        with bus.lock:
            check_camera(driver, bus, seen["shown"])
            check_boxes(driver, bus, seen["shown"], seen["drawn"])
            check_series(bus, seen["series"])
        labels = driver.execute_script("return window.slipstream.drawn.labels")
        for i, a in enumerate(labels):
            for b in labels[i + 1:]:
                apart = a["x"] + a["w"] <= b["x"] or b["x"] + b["w"] <= a["x"] or abs(a["y"] - b["y"]) >= 14
                assert apart, f"two labels print over each other: {a} {b}"
        rows = driver.execute_script("return document.querySelectorAll('#topics tbody tr').length")
        hops = driver.execute_script("return [...document.querySelectorAll('#hops tbody td')].map(td => td.textContent)")
        assert rows >= 8 and "frame -> applied" in hops, (rows, hops)
        driver.find_element("id", "freeze").click()
        time.sleep(1.5)
        REPORTS.mkdir(parents=True, exist_ok=True)
        height = driver.execute_script("return document.documentElement.scrollHeight")
        driver.set_window_size(1600, max(900, height + 40))
        shot = REPORTS / "view-page.png"
        driver.save_screenshot(str(shot))
        print(f"screenshot of the page: {shot}")
        assert shot.stat().st_size > 50_000
        errors = [e for e in driver.get_log("browser") if e["level"] == "SEVERE"]
        assert not errors, errors
    finally:
        if driver:
            driver.quit()
        if bus:
            bus.close()
        up.send_signal(signal.SIGINT)
        up.communicate(timeout=60)
    assert up.returncode in (0, 130), up.returncode


def wait_for_url(up, timeout=60):
    """The URL `up` prints for the view."""
    deadline = time.monotonic() + timeout
    lines = []
    while time.monotonic() < deadline:
        line = up.stderr.readline()
        assert line or up.poll() is None, "".join(lines)
        lines.append(line)
        if line.startswith("live view on "):
            return line.split()[3].rstrip(":").split(" ")[0]
    raise AssertionError("up printed no view URL: " + "".join(lines))


def http_get(port, path):
    try:
        with urllib.request.urlopen(f"http://127.0.0.1:{port}{path}", timeout=10) as r:
            return r.status, r.read()
    except urllib.error.HTTPError as e:
        return e.code, e.read()


def test_bad_requests_are_answered_counted_and_the_page_still_serves(slipstream_bin, free_port):
    port = free_tcp_port()
    started = time.monotonic()
    view = subprocess.Popen(
        [slipstream_bin, "-n", "webpage-bad", "-l", f"tcp/127.0.0.1:{free_port}", "view", "--view-port", str(port),
         "--duration", "30"], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, cwd=ROOT)
    try:
        deadline = time.monotonic() + 20
        while socket.socket().connect_ex(("127.0.0.1", port)) != 0:
            assert time.monotonic() < deadline and view.poll() is None, "the view never listened"
            time.sleep(0.2)
        assert http_get(port, "/no/such/page")[0] == 404
        with socket.create_connection(("127.0.0.1", port), timeout=5) as s:
            s.sendall(b"\x16\x03\x01\x02\x00 a TLS hello, not HTTP\r\n\r\n")
            assert s.recv(100).startswith(b"HTTP/1.1 400"), "bytes that are not HTTP get 400"
        for _ in range(20):  # clients gone mid-request and mid-answer
            with socket.create_connection(("127.0.0.1", port), timeout=5) as s:
                s.sendall(b"GET /state HTTP/1.1\r\nHo")
        # More WebSocket clients than the port serves at once, each sending what is not the
        # protocol and leaving without the closing handshake: none keeps its place.
        upgrade = (b"GET / HTTP/1.1\r\nHost: x\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
                   b"Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n"
                   b"Sec-WebSocket-Protocol: foxglove.sdk.v1\r\n\r\n")
        for _ in range(80):
            with socket.create_connection(("127.0.0.1", port), timeout=5) as s:
                s.sendall(upgrade)
                assert s.recv(12) == b"HTTP/1.1 101"
                s.sendall(b"\x81\x85\x00\x00\x00\x00hello")  # a text frame the server cannot parse
                s.shutdown(socket.SHUT_WR)
        status, body = http_get(port, "/")
        assert status == 200 and b"app.js" in body
        status, body = http_get(port, "/state")
        assert status == 200 and b'"bad_requests":2' in body, body[-400:]
        assert http_get(port, "/frame")[0] == 404, "no camera yet: a clear 404, not a stall"
    finally:
        view.send_signal(signal.SIGINT)
        _, err = view.communicate(timeout=30)
    # Each kind of bad request is logged at once, later ones counted into the next warning.
    assert err.count("view: ") <= 3, err
    assert "path the view does not have" in err, err
    assert "bad requests 2" in err, err
    # The Foxglove server says each message it cannot parse: shown once per 10 s, not 80 times
    # (a log written faster than it is read would block the view on its stderr).
    invalid = err.count("Invalid message from")
    assert 1 <= invalid <= 1 + (time.monotonic() - started) // 10, err


def replay_state(driver):
    return driver.execute_script("const s = window.slipstream; return s.last && s.last.replay")


def test_a_recording_in_the_page_plays_pauses_and_moves(slipstream_bin, free_port, tmp_path):
    """`slipstream view FILE.mcap`: the same page over a recording, replayed on a bus of its own,
    with play, pause and a time slider that moves the replay."""
    report = tmp_path / "run"
    # Real time: the recording spans 10 s of wall clock, the time its replay takes.
    subprocess.run([slipstream_bin, "-n", "webpage-rec", "-l", f"tcp/127.0.0.1:{free_port}", "up", "--scenario",
                    "cut-in", "--duration", "10", "--record", "--report", str(report), "--plain"],
                   check=True, capture_output=True, timeout=300, cwd=ROOT)
    port = free_tcp_port()
    view = subprocess.Popen([slipstream_bin, "view", str(report / "run.mcap"), "--view-port", str(port), "--duration",
                             "120"], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, cwd=ROOT)
    driver = None
    try:
        url = wait_for_url(view)
        # Nothing plays until a page asks: a state fetched without one finds it at its start.
        _, body = http_get(port, "/state")
        before = json.loads(body)["replay"]
        assert before["playing"] is False and before["t_s"] == 0 and before["rate"] == 1, before
        driver = chrome()
        driver.get(url)
        wait_until(driver, "const s = window.slipstream; return s.frames >= 3 && s.series.length > 20 && "
                           "s.last && s.last.replay", 60, "showed the recording")
        assert driver.find_element("id", "replay").is_displayed()
        duration = replay_state(driver)["duration_s"]
        assert duration and duration > 5, replay_state(driver)
        if not replay_state(driver)["playing"]:  # it ended already: play starts it over
            driver.find_element("id", "replay-play").click()
            wait_until(driver, "const r = window.slipstream.last.replay; return r && r.playing", 10, "played again")
        driver.find_element("id", "replay-play").click()  # pause
        wait_until(driver, "const r = window.slipstream.last.replay; return r && !r.playing", 10, "paused")
        held = replay_state(driver)["t_s"]
        time.sleep(1.0)
        assert replay_state(driver)["t_s"] == held, "a paused replay holds still"
        target = round(duration / 4, 1)
        driver.execute_script("const s = document.getElementById('replay-slider'); s.value = arguments[0];"
                              "s.dispatchEvent(new Event('change'))", str(target))
        wait_until(driver, f"const r = window.slipstream.last.replay; return r && Math.abs(r.t_s - {target}) < 0.05",
                   10, f"moved to {target} s")
        driver.find_element("id", "replay-play").click()  # play
        wait_until(driver, f"const r = window.slipstream.last.replay; return r && r.playing && r.t_s > {target} + 0.2",
                   20, "played on from there")
        driver.execute_script("const r = document.getElementById('replay-rate'); r.value = '4';"
                              "r.dispatchEvent(new Event('change'))")
        wait_until(driver, "const r = window.slipstream.last.replay; return r && r.rate === 4", 10, "took the speed")
        errors = [e for e in driver.get_log("browser") if e["level"] == "SEVERE"]
        assert not errors, errors
    finally:
        if driver:
            driver.quit()
        view.send_signal(signal.SIGINT)
        _, err = view.communicate(timeout=30)
    assert view.returncode == 0, err[-2000:]


FETCH = ("import sys, urllib.request as u\n"
         "for path in ('/', '/state', '/frame?w=160'):\n"
         "    with u.urlopen(sys.argv[1] + path, timeout=10) as r:\n"
         "        print(path, r.status, r.headers['Content-Type'], len(r.read()))\n")


def test_the_page_from_another_pc_on_the_lan(slipstream_bin):
    """`up --view --view-host 0.0.0.0` on the simulator's PC: a laptop on the LAN (another
    network namespace, joined by a bridge) gets the page, its state and a frame at the PC's
    address; a view on the default host is not reachable from there."""
    from netns import Lan, can_create_namespaces

    reason = can_create_namespaces()
    if reason:
        pytest.skip(reason)
    lan = Lan(["simpc", "laptop"], subnet="10.219.0")
    up = local = None
    try:
        up = lan.popen("simpc", [slipstream_bin, "-n", "lanview", "up", "--scenario", "cut-in", "--duration", "120",
                                 "--view", "--view-host", "0.0.0.0", "--plain"],
                       stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, cwd=ROOT)
        assert wait_for_url(up) == "http://localhost:8765"
        local = lan.popen("simpc", [slipstream_bin, "-n", "lanview", "view", "--view-port", "8766", "--duration", "60"],
                          stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, cwd=ROOT)
        assert wait_for_url(local) == "http://localhost:8766"
        got = ""
        deadline = time.monotonic() + 60
        while "/frame?w=160 200" not in got and time.monotonic() < deadline:
            fetch = lan.popen("laptop", [sys.executable, "-c", FETCH, f"http://{lan.addr['simpc']}:8765"],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
            got = fetch.communicate(timeout=60)[0]
            time.sleep(0.5)
        assert "/ 200 text/html" in got and "/state 200 application/json" in got, got
        assert "/frame?w=160 200 image/jpeg" in got, got
        refused = lan.popen("laptop", [sys.executable, "-c", FETCH, f"http://{lan.addr['simpc']}:8766"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        out, err = refused.communicate(timeout=60)
        assert refused.returncode != 0 and "Connection refused" in err, (out, err[-500:])
    finally:
        for proc in (local, up):
            if proc and proc.poll() is None:
                proc.send_signal(signal.SIGINT)
                proc.communicate(timeout=60)
        lan.close()
