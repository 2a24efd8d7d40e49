"""The Python client's examples run against the Rust nodes, and a Python subscriber decodes
every message type the Rust side publishes during `slipstream up`."""

import json
import re
import signal
import subprocess
import sys
import threading
import time

import zenoh
import zenoh.ext
from conftest import ROOT, peer_config

from slipstream_client import KINDS, Topics, decode, encode

EXAMPLES = ROOT / "clients" / "python" / "examples"


def example(name, *args, timeout=60):
    return subprocess.run([sys.executable, str(EXAMPLES / name), *args], capture_output=True, text=True,
                          timeout=timeout, cwd=ROOT)


def test_examples_and_every_published_type_decode_during_up(slipstream_bin, free_port, tmp_path):
    endpoint = f"tcp/127.0.0.1:{free_port}"
    up = subprocess.Popen(
        [slipstream_bin, "-l", endpoint, "up", "--scenario", "steady-follow", "--duration", "14", "--plain",
         "--report", str(tmp_path / "report")],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
    )
    try:
        kinds, errors, statuses = {}, [], []
        lock = threading.Lock()
        topics = Topics()

        def on_sample(sample):
            key = str(sample.key_expr)
            expected = topics.kind(key)
            if expected is None:  # liveliness and zenoh-ext keys
                return
            try:
                kind, _, body = decode(sample.payload.to_bytes(), expected=expected)
            except Exception as e:
                with lock:
                    errors.append((key, repr(e)))
                return
            with lock:
                kinds[kind] = kinds.get(kind, 0) + 1
                if kind == "AccStatus":
                    statuses.append(body)

        with zenoh.open(peer_config(endpoint)) as session:
            sub = session.declare_subscriber("**", on_sample)
            # The latched topics (camera info, the road): their history, whenever they were sent.
            latched = [
                zenoh.ext.declare_advanced_subscriber(
                    session, key, on_sample, history=zenoh.ext.HistoryConfig(detect_late_publishers=True))
                for key in ("camera/front/info", "sim/road", "sim/ego")
            ]
            # The loop runs before the examples join (on a loaded machine `up` takes seconds to
            # start, and an example that dials before anyone listens waits out its timeout).
            started = time.monotonic() + 60
            while time.monotonic() < started and not kinds.get("Speed"):
                time.sleep(0.05)
            assert kinds.get("Speed"), f"the loop never ran: {kinds}"
            speed = example("print_speed.py", "-e", endpoint, "--count", "50")
            camera = example("camera_numpy.py", "-e", endpoint, "--count", "5")
            # An operator command from Python: the Rust ACC takes the new set speed.
            command = {"enable": True, "set_speed_mps": 23.5, "time_gap_s": None}
            session.put("acc/command", encode("AccCommand", {"seq": 0, "stamp_sim_ns": 0, "stamp_pub_ns": time.time_ns()},
                                              command))
            deadline = time.monotonic() + 10
            while time.monotonic() < deadline:
                with lock:
                    if statuses and statuses[-1]["set_speed_mps"] == 23.5:
                        break
                time.sleep(0.1)
            up.wait(timeout=90)  # subscribed to the end: sim/events carries ScenarioEnd
            for s in latched:
                s.undeclare()
            sub.undeclare()
    finally:
        if up.poll() is None:
            up.kill()
            up.wait(timeout=10)
    assert speed.returncode == 0, speed.stderr
    lines = [l for l in speed.stdout.splitlines() if l.startswith("t=")]
    assert len(lines) == 50 and all(" m/s " in l for l in lines), speed.stdout[-500:]
    assert camera.returncode == 0, camera.stderr
    frames = [l for l in camera.stdout.splitlines() if l.startswith("frame")]
    assert len(frames) == 5 and all("(480, 640, 3) uint8 Rgb8" in l for l in frames), camera.stdout
    assert "# camera 640x480 at 20 Hz" in camera.stdout, camera.stdout
    assert not errors, errors[:5]
    # Every type the Rust nodes publish: all but AccCommand, which operators send (this
    # session's own AccCommand reached its own subscriber too).
    assert set(kinds) == set(KINDS.values()), kinds
    assert statuses[-1]["set_speed_mps"] == 23.5, statuses[-1]
    assert up.returncode == 0


def test_python_cruise_controller_closes_the_loop_with_the_rust_simulator(sim_bin, free_port):
    endpoint = f"tcp/127.0.0.1:{free_port}"
    sim = subprocess.Popen(
        [sim_bin, "--scenario", "approach-slower-lead", "--duration", "25", "--camera-size", "160x120", "--json",
         "-l", endpoint, "-e", endpoint],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )
    try:
        controller = subprocess.Popen(
            [sys.executable, str(EXAMPLES / "cruise_controller.py"), "-e", endpoint, "--set-speed", "30",
             "--duration", "40"],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT,
        )
        out, err = sim.communicate(timeout=90)
        controller.send_signal(signal.SIGINT)  # Ctrl-C: it undeclares, closes and prints its totals
        c_out, c_err = controller.communicate(timeout=20)
    finally:
        for p in (sim, controller):
            if p.poll() is None:
                p.kill()
                p.wait(timeout=10)
    report = json.loads(out)
    assert sim.returncode == 0, err[-2000:]
    assert report["end"]["success"] and report["ego_collisions"] == 0, report
    # The Python controller kept the loop closed: the simulator never had to brake for lack of commands.
    assert report["control_timeouts"] == 0, report
    # It followed the slower lead: the last printed lines show about the lead's 20 m/s at ~1.8 s gap.
    rows = [l for l in c_out.splitlines() if l.startswith("t=")]
    assert len(rows) > 15, c_out + c_err
    m = re.search(r"speed\s+([\d.]+) m/s\s+lead gap\s+([\d.]+) m", rows[-1])
    assert m, rows[-1]
    speed, gap = float(m.group(1)), float(m.group(2))
    assert 18.5 < speed < 21.5 and 30 < gap < 55, rows[-3:]
    assert "# sent" in c_out and "0 undecodable" in c_out, c_out[-300:]
