"""Bad input from outside: a Python client publishes random bytes, truncated messages, other
wire versions and the wrong message type on every key while `slipstream up` runs the loop.
No node crashes or stalls, the loop keeps running, and the errors show in the nodes' logs,
the simulator's report and the per-sender statistics of up's report."""

import json
import random
import subprocess
import time

import zenoh
from conftest import peer_config

from slipstream_client import DEFAULT_KEYS, WireError, decode


def bad_payloads(examples, kind, rng):
    """Payloads that must not decode as `kind`: none of them is a valid message of that kind."""
    good = examples[kind]
    other = next(b for k, b in examples.items() if k != kind)
    out = [
        b"",
        good[:1],
        good[: len(good) // 2],  # truncated
        bytes([good[0] + 1]) + good[1:],  # a newer wire version
        bytes([1]) + good[1:],  # the version before the loop trace
        good + b"\x00",  # trailing byte
        other,  # another message type on this key
        bytes(rng.randrange(256) for _ in range(rng.randrange(1, 200))),
    ]
    for p in out:
        try:
            decode(p, expected=kind)
        except WireError:
            continue
        raise AssertionError(f"{p!r} decodes as {kind}")
    return out


# A namespace of the test's own: a loop in the default one (another test's) moves `up` away.
NS = "fuzzed"


def test_garbage_on_every_key_neither_crashes_nor_stalls_the_loop(slipstream_bin, free_port, tmp_path):
    out = subprocess.run([slipstream_bin, "wire-examples"], check=True, capture_output=True, text=True, timeout=60)
    examples = {e["kind"]: bytes.fromhex(e["hex"].replace(" ", "")) for e in json.loads(out.stdout)}
    endpoint = f"tcp/127.0.0.1:{free_port}"
    report_dir = tmp_path / "report"
    up = subprocess.Popen(
        [slipstream_bin, "-l", endpoint, "-n", NS, "up", "--duration", "12", "--plain", "--report", str(report_dir)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    sent = 0
    try:
        rng = random.Random(7)
        session = zenoh.open(peer_config(endpoint))
        try:
            # The loop runs (its states arrive): on a loaded machine `up` takes seconds to start.
            states = []
            watch = session.declare_subscriber(f"{NS}/vehicle/state", lambda _: states.append(1))
            started = time.monotonic() + 60
            while not states and time.monotonic() < started:
                time.sleep(0.05)
            watch.undeclare()
            assert states, "the loop never ran"
            deadline = time.monotonic() + 5
            while time.monotonic() < deadline and sent < 20_000:
                for key, kind in DEFAULT_KEYS.items():
                    for p in bad_payloads(examples, kind, rng):
                        session.put(f"{NS}/{key}", p, attachment=b"fuzz")
                        sent += 1
                time.sleep(0.02)
        finally:
            session.close()
        code = up.wait(timeout=90)
    finally:
        if up.poll() is None:
            up.kill()
    assert sent > 1000
    report = json.loads((report_dir / "report.json").read_text())
    assert code == 0, report
    # The loop ran to the end, every node exited cleanly.
    assert abs(report["sim_time_s"] - 12) < 0.1
    assert all(n["exit_code"] == 0 and not n["died"] for n in report["nodes"]), report["nodes"]
    hops = {h["hop"]: h for h in report["latency"]["hops"]}
    # The loop kept closing under the garbage (how often is a figure of the machine's load).
    assert hops["frame -> applied"]["count"] > 0, hops
    # Per sender: every key got bad payloads from "fuzz", counted, and none decoded.
    fuzz = {r["key"].removeprefix(f"{NS}/"): r for r in report["topics"] if r["from"] == "fuzz"}
    assert set(fuzz) == set(DEFAULT_KEYS), sorted(fuzz)
    for key, row in fuzz.items():
        assert row["decode_errors"] > 0 and row["received"] == 0, (key, row)
    # The nodes counted and logged them, rate-limited: a few lines, not thousands.
    sim_report = json.loads((report_dir / "logs" / "slipstream-sim.json").read_text())
    assert sim_report["control_rejected"] > 100, sim_report
    for node in ("slipstream-acc", "slipstream-detect", "slipstream-sim"):
        log = (report_dir / "logs" / f"{node}.log").read_text()
        dropped = [line for line in log.splitlines() if "dropped malformed payload" in line]
        assert 0 < len(dropped) < 100, (node, len(dropped))
