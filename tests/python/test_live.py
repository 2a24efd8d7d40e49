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


def test_link_copies_decode_with_an_independent_lz4_and_match_the_raw_frames(slipstream_bin, free_port):
    """camera/front/@lz4 and camera/front/@jpeg (link copies, config/slipstream.json5) beside raw
    camera/front: the LZ4 block expands, with the `lz4` package (not our decoder), to exactly
    the raw frame of the same seq; the JPEG copy is a JPEG with the same header."""
    import lz4.block

    from slipstream_client.image import frame_array

    endpoint = f"tcp/127.0.0.1:{free_port}"
    publisher = subprocess.Popen(
        [slipstream_bin, "demo", "--role", "pub", "--duration", "8", "-l", endpoint, "-e", endpoint],
        stdout=subprocess.DEVNULL,
    )
    try:
        got = {"camera/front": {}, "camera/front/@lz4": {}, "camera/front/@jpeg": {}}
        lock = threading.Lock()

        def on_sample(sample):
            payload = sample.payload.to_bytes()
            _, header, body = decode(payload)
            with lock:
                got[str(sample.key_expr)][header["seq"]] = (header, body, payload)

        with zenoh.open(peer_config(endpoint)) as session:
            subs = [session.declare_subscriber(k, on_sample) for k in got]
            deadline = time.time() + 20
            while time.time() < deadline:
                with lock:
                    common = set(got["camera/front"]) & set(got["camera/front/@lz4"]) & set(got["camera/front/@jpeg"])
                if len(common) >= 3:
                    break
                time.sleep(0.1)
            for s in subs:
                s.undeclare()
        assert len(common) >= 3, {k: len(v) for k, v in got.items()}
        for seq in sorted(common)[:3]:
            raw_h, raw, _ = got["camera/front"][seq]
            lz_h, lz, lz_payload = got["camera/front/@lz4"][seq]
            jp_h, jp, _ = got["camera/front/@jpeg"][seq]
            assert raw_h == lz_h == jp_h, "a copy carries its frame's header"
            assert (lz["encoding"], jp["encoding"]) == ("Lz4", "Jpeg")
            pixels = lz4.block.decompress(bytes(lz["data"]), uncompressed_size=640 * 480 * 3)
            assert pixels == bytes(raw["data"]), "bit-exact"
            assert len(lz["data"]) < len(raw["data"]) / 3
            assert bytes(jp["data"][:2]) == b"\xff\xd8" and len(jp["data"]) < len(raw["data"]) / 10
            # The client's own reader agrees.
            _, _, array = frame_array(lz_payload)
            assert array.tobytes() == pixels
    finally:
        publisher.kill()
        publisher.wait(timeout=10)
