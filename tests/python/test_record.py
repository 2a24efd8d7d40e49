"""Recordings read by an independent MCAP reader (the `mcap` package): `slipstream up --record`
and `slipstream record` keep every payload byte for byte, one channel per key, schemas and
encodings as docs/recording.md says, and account for every sequence number."""

import json
import os
import subprocess
import sys
from collections import defaultdict

import pytest
from conftest import ROOT, reserve_port

from slipstream_client import decode
from slipstream_client.wire import WIRE_VERSION

mcap_reader = pytest.importorskip("mcap.reader", reason="scripts/test.sh installs the mcap package")
from mcap.stream_reader import StreamReader  # noqa: E402

WIRE = f"slipstream/v{WIRE_VERSION}"


def read_all(path):
    """(summary, metadata dict, [(channel, message)]) through the indexed reader."""
    with open(path, "rb") as f:
        reader = mcap_reader.make_reader(f)
        summary = reader.get_summary()
        meta = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
        messages = [(channel, message) for _, channel, message in reader.iter_messages(log_time_order=False)]
    return summary, meta, messages


def check_recording(path):
    """Every property a recording promises; returns the channels' topics and the metadata.
    Viewable copies (`--viewable`) are left out: they are checked on their own."""
    summary, meta, messages = read_all(path)
    summary.channels = {i: c for i, c in summary.channels.items() if "viewable_copy" not in c.metadata}
    messages = [(c, m) for c, m in messages if "viewable_copy" not in c.metadata]
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
        # MCAP's meaning: published when the publisher stamped it, logged when the recorder
        # received it (one host, one clock: not before).
        assert message.publish_time == header["stamp_pub_ns"] and message.log_time >= message.publish_time
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
    viewable = int(meta["slipstream.recording"].get("viewable_copies_written", 0))
    assert int(info["messages"]) == len(messages) == summary.statistics.message_count - viewable
    return channels, info


@pytest.fixture(scope="module")
def lockstep_run(slipstream_bin, tmp_path_factory):
    """One recorded lockstep run of `up` (6 s simulated), shared by the tests of this module:
    (report dir, the finished process)."""
    report = tmp_path_factory.mktemp("lockstep") / "report"
    port = reserve_port()
    run = subprocess.run(
        [slipstream_bin, "-l", f"tcp/127.0.0.1:{port}", "up", "--mode", "lockstep", "--duration", "6",
         "--record", "--plain", "--report", str(report)],
        capture_output=True, text=True, timeout=300, cwd=ROOT)
    return report, run


def test_up_record_is_read_whole_by_an_independent_reader(lockstep_run):
    report, run = lockstep_run
    up = json.loads((report / "report.json").read_text())
    rec = up["recording"]
    assert rec is not None, run.stderr[-2000:]
    lost = rec["lost_upstream"] + rec["dropped_by_recorder"]
    # The exit code says whether the recording lost anything (and nothing else went wrong).
    assert run.returncode == (1 if lost else 0), (run.returncode, rec, run.stderr[-2000:])
    channels, info = check_recording(report / "run.mcap")
    # What the loop publishes, each key its own channel; frames and detections among them.
    for key in ("vehicle/speed", "vehicle/state", "vehicle/control", "camera/front", "camera/front/info",
                "camera/narrow", "camera/narrow/info", "objects", "perception/objects", "sim/clock", "sim/events",
                "acc/status"):
        assert key in channels, sorted(channels)
    # The same keys `up` saw on the bus (its `top` view).
    seen = {row["key"] for row in up["topics"]}
    assert seen == set(channels), (seen, set(channels))
    assert channels["camera/front"]["messages"] > 50
    assert int(info["wire_version"]) == WIRE_VERSION and info["namespace"] == ""


def test_the_mcap_package_decodes_every_channel_from_the_schema_it_carries(lockstep_run):
    """`iter_decoded_messages` with the client's DecoderFactory: each channel decoded from its
    own schema record's layout (docs/recording.md), equal to the client's own decoder, for
    every message of the recording."""
    from slipstream_client.mcap_decoder import SCHEMA_ENCODING, DecoderFactory
    report, _ = lockstep_run
    kinds = defaultdict(int)
    with open(report / "run.mcap", "rb") as f:
        reader = mcap_reader.make_reader(f, decoder_factories=[DecoderFactory()])
        for schema, channel, message, decoded in reader.iter_decoded_messages(log_time_order=False):
            assert schema.encoding == SCHEMA_ENCODING and schema.name == "slipstream." + json.loads(schema.data)["name"]
            assert decoded == decode(message.data), channel.topic
            kinds[decoded[0]] += 1
    assert {"Speed", "VehicleState", "ControlCommand", "CameraFrame", "CameraInfo", "GroundTruthObjects",
            "Detections", "SimClock", "SimEvent", "AccStatus"} <= set(kinds), dict(kinds)


def test_a_layout_decodes_its_own_wire_version_and_refuses_what_does_not_fit(lockstep_run):
    """The layout, not the client's version, says how to read: a channel whose schema carries
    another wire version decodes payloads of that version; bytes that do not fit are refused."""
    from slipstream_client.mcap_decoder import Layout
    from slipstream_client.wire import WireError
    report, _ = lockstep_run
    with open(report / "run.mcap", "rb") as f:
        reader = mcap_reader.make_reader(f)
        schema, _, message = next(m for m in reader.iter_messages() if m[0].name == "slipstream.VehicleState")
    doc = json.loads(schema.data)
    doc["wire_version"] = WIRE_VERSION + 1
    other = Layout(json.dumps(doc).encode())
    payload = bytes([WIRE_VERSION + 1]) + message.data[1:]
    assert other.decode(payload)[1:] == decode(message.data)[1:]
    for bad in (message.data, payload + b"\x00", payload[:-3], payload[:1]):
        with pytest.raises(WireError):
            other.decode(bad)
    with pytest.raises(WireError):
        Layout(b"{}")


def test_a_cut_recording_reads_up_to_its_last_chunk(slipstream_bin, sim_bin, free_port, tmp_path):
    """A file cut short (a crash, a full disk) still yields its complete chunks to a reader
    that streams it without the summary at the end (docs/recording.md)."""
    endpoint = f"tcp/127.0.0.1:{free_port}"
    path = tmp_path / "full.mcap"
    sim = subprocess.Popen([sim_bin, "--scenario", "open-road", "--mode", "realtime", "--duration", "60",
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


def resim(slipstream_bin, free_port, recording, report, env=None, more=()):
    run = subprocess.run(
        [slipstream_bin, "-l", f"tcp/127.0.0.1:{free_port}", "up", "--from", str(recording), "--plain",
         "--report", str(report), *more],
        capture_output=True, text=True, timeout=300, cwd=ROOT, env=env)
    assert (report / "report.json").is_file(), (run.returncode, run.stdout, run.stderr[-3000:])
    return run, json.loads((report / "report.json").read_text())


def test_a_lockstep_recording_replays_into_the_same_nodes_byte_for_byte(slipstream_bin, free_port, lockstep_run,
                                                                         tmp_path):
    """copper's record == replay check: the recorded camera, speed and state drive today's
    detector and ACC in place of the simulator; they answer with the same bytes (wall-clock
    stamps aside), every frame and every step."""
    recording = lockstep_run[0] / "run.mcap"
    run, r = resim(slipstream_bin, free_port, recording, tmp_path / "resim")
    assert run.returncode == 0, (run.stdout, run.stderr[-3000:])
    assert (r["clock"], r["perception"], r["scenario"]) == ("lockstep", "camera", "cut-in"), r
    d, c = r["detections"], r["commands"]
    _, _, messages = read_all(recording)
    recorded = {"perception/objects": 0, "vehicle/control": 0}
    for channel, _ in messages:
        if channel.topic in recorded:
            recorded[channel.topic] += 1
    # Every frame's detections and every step's command, answered the same.
    assert d["recorded"] == recorded["perception/objects"] > 50, (d, recorded)
    assert d["identical"] == d["recorded"] == d["replayed"], d
    assert c["recorded"] > 500 and c["identical"] == c["recorded"] == c["replayed"], c
    assert (d["differing"], d["missing"], d["extra"], c["differing"], c["missing"]) == (0, 0, 0, 0, 0)
    assert r["replay"]["steps_timed_out"] == 0
    assert "answer exactly as recorded" in run.stdout, run.stdout


def test_the_documented_loop_file_answers_a_recording_as_todays_loop_byte_for_byte(slipstream_bin, free_port,
                                                                                  lockstep_run, tmp_path):
    """config/loop.json5 spells out today's loop (our node in every role): replayed into it,
    the recording of a run without a loop file is answered with the same bytes."""
    run, r = resim(slipstream_bin, free_port, lockstep_run[0] / "run.mcap", tmp_path / "resim",
                   more=("--loop", "config/loop.json5"))
    assert run.returncode == 0, (run.stdout, run.stderr[-3000:])
    d, c = r["detections"], r["commands"]
    assert d["identical"] == d["recorded"] > 50 and c["identical"] == c["recorded"] > 500, (d, c)
    assert (d["differing"], d["missing"], c["differing"], c["missing"]) == (0, 0, 0, 0)
    assert r["own"]["loop_file"]["path"] == "config/loop.json5", r["own"]
    assert set(r["own"]["builtin"]) == {"simulator", "detector", "controller"}, r["own"]


def test_a_python_controller_answers_a_recording_in_the_place_of_ours(slipstream_bin, free_port, lockstep_run,
                                                                      tmp_path):
    """`up --from` replays into a controller of the user's own: every step answered, the
    differences from slipstream-acc's answers counted."""
    controller = f"{sys.executable} clients/python/examples/own_acc.py"
    run, r = resim(slipstream_bin, free_port, lockstep_run[0] / "run.mcap", tmp_path / "resim",
                   more=("--controller", controller))
    assert run.returncode == 0, (run.stdout, run.stderr[-3000:])
    c = r["commands"]
    assert c["replayed"] == c["recorded"] > 500 and c["missing"] == 0 and c["differing"] > 0, c
    assert r["replay"]["steps_timed_out"] == 0, r["replay"]
    assert r["own"]["controller"]["command"][1] == "clients/python/examples/own_acc.py"
    assert r["detections"]["identical"] == r["detections"]["recorded"], "the detector is ours, unchanged"


def test_a_changed_controller_is_shown_where_it_first_answers_differently(slipstream_bin, free_port, lockstep_run,
                                                                          tmp_path):
    """The same recording into an ACC with another time gap (its config file): the detector's
    answers stay the same, the commands differ and the report names the first one."""
    config = (ROOT / "config" / "acc.json5").read_text()
    assert "time_gap_s: 1.8," in config
    changed = tmp_path / "acc.json5"
    changed.write_text(config.replace("time_gap_s: 1.8,", "time_gap_s: 1.0,"))
    env = dict(os.environ, SLIPSTREAM_ACC_CONFIG=str(changed))
    run, r = resim(slipstream_bin, free_port, lockstep_run[0] / "run.mcap", tmp_path / "resim", env)
    assert run.returncode == 0, (run.stdout, run.stderr[-3000:])
    d, c = r["detections"], r["commands"]
    assert d["identical"] == d["recorded"] > 0 and d["differing"] == 0, d
    assert c["differing"] > 0 and c["max_abs_difference"] > 0, c
    first = c["first_difference"]
    assert first["answers"].startswith("the speed at ") and first["recorded"] != first["replayed"], first
    assert "first difference" in run.stdout and "answer differently" in run.stdout, run.stdout


def test_viewable_copies_stand_beside_the_payloads(slipstream_bin, free_port, tmp_path):
    """`up --record --viewable`: next to the byte-for-byte channels, Foxglove's schemas on the
    live view's topics, one copy per frame, per detections and per state."""
    report = tmp_path / "report"
    run = subprocess.run(
        [slipstream_bin, "-l", f"tcp/127.0.0.1:{free_port}", "up", "--mode", "lockstep", "--duration", "3",
         "--record", "--viewable", "--plain", "--report", str(report)],
        capture_output=True, text=True, timeout=300, cwd=ROOT)
    assert (report / "run.mcap").is_file(), run.stderr[-2000:]
    channels, info = check_recording(report / "run.mcap")
    assert info["viewable_copies"] == "true"
    summary, _, messages = read_all(report / "run.mcap")
    counts = defaultdict(int)
    for channel, _ in messages:
        counts[channel.topic] += 1
    schemas = {c.topic: summary.schemas[c.schema_id] for c in summary.channels.values()}
    expected = {"/camera/front": "foxglove.RawImage", "/camera/front/calibration": "foxglove.CameraCalibration",
                "/camera/front/annotations": "foxglove.ImageAnnotations", "/scene/vehicles": "foxglove.SceneUpdate",
                "/scene/road": "foxglove.SceneUpdate", "/tf": "foxglove.FrameTransforms",
                "/acc": "slipstream.view.AccSeries"}
    for topic, name in expected.items():
        assert schemas[topic].name == name, (topic, schemas[topic].name)
        assert schemas[topic].encoding == ("jsonschema" if topic == "/acc" else "protobuf")
        assert len(schemas[topic].data) > 0, topic
    up = json.loads((report / "report.json").read_text())
    pairs = [("/camera/front", "camera/front"), ("/camera/front/annotations", "perception/objects"),
             ("/scene/vehicles", "vehicle/state"), ("/acc", "vehicle/state")]
    if up["recording"]["viewable_skipped"] == 0:
        # One copy per frame, per detections message and per state.
        for copy, original in pairs:
            assert counts[copy] == counts[original] > 0, (copy, counts[copy], original, counts[original])
    else:
        # The writer fell behind (a loaded machine): copies were skipped, payloads never.
        for copy, original in pairs:
            assert 0 < counts[copy] <= counts[original], (copy, counts[copy], original, counts[original])
    assert 0 < counts["/scene/road"] <= 4, "the road once per simulated second"
    assert up["recording"]["viewable_copies"] == sum(counts[t] for t in expected)
    assert int(info["viewable_copies_written"]) == up["recording"]["viewable_copies"]
