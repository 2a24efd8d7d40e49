"""A Python eclipse-zenoh subscriber reads what the Rust nodes publish, with no Rust code."""

import subprocess
import threading
import time

import zenoh
from conftest import peer_config

from slipstream_client import decode, encoding_schema


def test_python_subscriber_decodes_rust_publications(slipstream_bin, free_port):
    endpoint = f"tcp/127.0.0.1:{free_port}"
    publisher = subprocess.Popen(
        [slipstream_bin, "demo", "--role", "pub", "--duration", "8", "-l", endpoint, "-e", endpoint],
        stdout=subprocess.DEVNULL,
    )
    try:
        conf = peer_config(endpoint)
        got = {"Speed": [], "CameraFrame": [], "SimClock": []}
        encodings = set()
        lock = threading.Lock()

        def on_sample(sample):
            kind, header, body = decode(sample.payload.to_bytes())
            with lock:
                got[kind].append((header, body))
                encodings.add(str(sample.encoding))

        with zenoh.open(conf) as session:
            subs = [session.declare_subscriber(k, on_sample) for k in ("vehicle/speed", "camera/front", "sim/clock")]
            deadline = time.time() + 20
            while time.time() < deadline:
                with lock:
                    if len(got["Speed"]) >= 100 and len(got["CameraFrame"]) >= 10:
                        break
                time.sleep(0.1)
            for s in subs:
                s.undeclare()
        assert len(got["Speed"]) >= 100, {k: len(v) for k, v in got.items()}
        assert len(got["CameraFrame"]) >= 10
        seqs = [h["seq"] for h, _ in got["Speed"]]
        # Speed is published with congestion control "drop": a loaded machine may lose one, so
        # the test asserts order and no repeats, not a loss count.
        assert all(a < b for a, b in zip(seqs, seqs[1:])), "in order, none twice"
        assert all(15.0 <= b["speed_mps"] <= 25.0 for _, b in got["Speed"])
        h, frame = got["CameraFrame"][-1]
        assert (frame["width"], frame["height"], frame["encoding"]) == (640, 480, "Rgb8")
        assert len(frame["data"]) == 640 * 480 * 3
        assert 0 < h["stamp_pub_ns"] <= time.time_ns()
        assert f"application/octet-stream;{encoding_schema('Speed')}" in encodings, encodings
    finally:
        publisher.kill()
        publisher.wait(timeout=10)
