"""Recordings read by an independent MCAP reader (the `mcap` package): `slipstream up --record`
and `slipstream record` keep every payload byte for byte, one channel per key, schemas and
encodings as docs/recording.md says, and account for every sequence number."""

import json
import subprocess
from collections import defaultdict

import pytest
from conftest import ROOT

from slipstream_client import decode

mcap_reader = pytest.importorskip("mcap.reader", reason="scripts/test.sh installs the mcap package")
from mcap.stream_reader import StreamReader  # noqa: E402

WIRE = "slipstream/v2"


def read_all(path):
    """(summary, metadata dict, [(channel, message)]) through the indexed reader."""
    with open(path, "rb") as f:
        reader = mcap_reader.make_reader(f)
        summary = reader.get_summary()
        meta = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
        messages = [(channel, message) for _, channel, message in reader.iter_messages(log_time_order=False)]
    return summary, meta, messages


def check_recording(path):
    """Every property a recording promises; returns the channels' topics and the metadata."""
    summary, meta, messages = read_all(path)
    assert "slipstream.recording" in meta, meta.keys()
    info = meta["slipstream.recording"]
    channels = {c["topic"]: c for c in json.loads(info["channels"])}
    # One channel per key here (each key has one type and one publisher), named after the type.
    topics = [c.topic for c in summary.channels.values()]
    assert len(topics) == len(set(topics)), topics
    assert set(topics) == set(channels), (topics, channels.keys())
    for c in summary.channels.values():
        assert c.metadata.get("publisher") == channels[c.topic]["publisher"], (c.topic, c.metadata)
    spans = {}  # topic -> [min seq, max seq]
    counts = defaultdict(int)
    last_time = {}
    for channel, message in messages:
        schema = summary.schemas[channel.schema_id]
        kind, header, _ = decode(message.data)  # lossless: every payload decodes strictly
        assert schema.name == f"slipstream.{kind}", (channel.topic, schema.name, kind)
        assert channel.message_encoding == WIRE
        assert message.log_time == header["stamp_pub_ns"] == message.publish_time
        assert message.sequence == header["seq"] & 0xFFFFFFFF
        span = spans.setdefault(channel.topic, [header["seq"], header["seq"]])
        span[0], span[1] = min(span[0], header["seq"]), max(span[1], header["seq"])
        # Per channel, in the file's order, time never goes back.
        assert message.log_time >= last_time.get(channel.id, 0), channel.topic
        last_time[channel.id] = message.log_time
        counts[channel.topic] += 1
    for topic, c in channels.items():
        assert c["messages"] == counts[topic], (topic, c, counts[topic])
        # Every sequence number is accounted for: in the file, or counted as lost.
        lo, hi = spans[topic]
        assert c["messages"] + c["lost_upstream"] == hi - lo + 1, (topic, c, spans[topic])
    assert int(info["messages"]) == len(messages) == summary.statistics.message_count
    return channels, info


def test_up_record_is_read_whole_by_an_independent_reader(slipstream_bin, free_port, tmp_path):
    report = tmp_path / "report"
    run = subprocess.run(
        [slipstream_bin, "-l", f"tcp/127.0.0.1:{free_port}", "up", "--mode", "lockstep", "--duration", "6",
         "--record", "--plain", "--report", str(report)],
        capture_output=True, text=True, timeout=300, cwd=ROOT)
    up = json.loads((report / "report.json").read_text())
    rec = up["recording"]
    assert rec is not None, run.stderr[-2000:]
    lost = rec["lost_upstream"] + rec["dropped_by_recorder"]
    # The exit code says whether the recording lost anything (and nothing else went wrong).
    assert run.returncode == (1 if lost else 0), (run.returncode, rec, run.stderr[-2000:])
    channels, info = check_recording(report / "run.mcap")
    # What the loop publishes, each key its own channel; frames and detections among them.
    for key in ("vehicle/speed", "vehicle/state", "vehicle/control", "camera/front", "camera/front/info",
                "objects", "perception/objects", "sim/clock", "sim/events", "acc/status"):
        assert key in channels, sorted(channels)
    # The same keys `up` saw on the bus (its `top` view).
    seen = {row["key"] for row in up["topics"]}
    assert seen == set(channels), (seen, set(channels))
    assert channels["camera/front"]["messages"] > 50
    assert int(info["wire_version"]) == 2 and info["namespace"] == ""


def test_a_cut_recording_reads_up_to_its_last_chunk(slipstream_bin, sim_bin, free_port, tmp_path):
    """A file cut short (a crash, a full disk) still yields its complete chunks to a reader
    that streams it without the summary at the end (docs/recording.md)."""
    endpoint = f"tcp/127.0.0.1:{free_port}"
    path = tmp_path / "full.mcap"
    sim = subprocess.Popen([sim_bin, "--scenario", "open-road", "--clock", "realtime", "--duration", "60",
                            "-l", endpoint], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        run = subprocess.run([slipstream_bin, "-e", endpoint, "record", "-o", str(path), "--duration", "4",
                              "vehicle/speed", "camera/front"], capture_output=True, text=True, timeout=120,
                             cwd=ROOT)
    finally:
        sim.kill()
        sim.wait(timeout=10)
    assert path.is_file(), run.stderr
    channels, info = check_recording(path)
    lost = int(info["lost_upstream"]) + int(info["dropped_by_recorder"])
    assert run.returncode == (1 if lost else 0), (run.returncode, run.stdout, run.stderr)
    assert set(channels) == {"vehicle/speed", "camera/front"}, channels.keys()
    assert "nothing lost" in run.stdout or "LOST" in run.stdout, run.stdout

    full = path.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(full[: len(full) * 2 // 3])
    got, complete = 0, False
    with open(cut, "rb") as f:
        try:
            for record in StreamReader(f, skip_magic=False).records:
                got += type(record).__name__ == "Message"
        except Exception:  # the cut record at the end
            complete = True
    assert complete, "the cut file should end in a partial record"
    assert got > 0, "messages before the cut are readable"
