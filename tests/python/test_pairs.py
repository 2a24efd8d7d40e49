"""The tools in the pairs users combine them, typed as a user types them on a host of its own
(tests/python/user_host.py: the default config and port, the default namespace).

Each capability is proven alone elsewhere; here two or three run at once: a replay beside a
live loop, a recorder beside a replay, the view of every kind of recording, re-simulation of a
realtime recording that lost messages, the root namespace's tools beside two loops and a
stranger's publisher, and an evaluation whose controller dies in its second scenario.
"""

import json
import signal
import textwrap
import time

import pytest
from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer
from user_host import UserHost, can_create

NO_HOST = can_create()
pytestmark = pytest.mark.skipif(NO_HOST is not None, reason=f"a host of its own: {NO_HOST}")


@pytest.fixture
def host(tmp_path):
    h = UserHost(tmp_path)
    try:
        yield h
        assert not h.leftovers(), f"processes left behind: {h.leftovers()}"
    finally:
        h.close()


def finished(host, command, expect=0, timeout=180):
    """Runs `command` to its end; checks its exit code (`expect=None`: 0, or 1 for a realtime
    recording whose recorder counted a loss on a loaded machine)."""
    p = host.run(command, timeout)
    allowed = (0, 1) if expect is None else (expect,)
    assert p.code in allowed, f"`{command}` exited {p.code}, not {expect}:\n{p.stderr()[-3000:]}"
    return p


def channels(path):
    with open(path, "rb") as f:
        return list(make_reader(f).get_summary().channels.values())


def report(host, directory):
    return json.loads((host.dir / directory / "report.json").read_text())


def test_a_replay_beside_a_live_loop_is_refused_then_never_taken_for_live(host):
    finished(host, "slipstream up --mode lockstep --duration 6 --record --report base --plain")
    up = host.start("slipstream up --perception ground-truth --duration 20 --report live --plain")
    host.wait_for(up, "nodes alive: acc, sim, up", 60)
    refused = finished(host, "slipstream play base/run.mcap", expect=1)
    said = refused.stderr()
    assert "a live loop runs in the default namespace" in said and "acc, sim" in said and "--into-live" in said, said
    player = host.start("slipstream play base/run.mcap --into-live --loop --rate 4")
    host.wait_for(player, "played base/run.mcap", 30)
    top = finished(host, "slipstream top --json --duration 3", timeout=30)
    last = json.loads(top.stdout().splitlines()[-1])
    assert any(n.startswith("play-") for n in last["nodes"]), last["nodes"]
    rows = {(k["key"], k["from"]): k for k in last["keys"]}
    replayed = rows[("vehicle/speed", "sim@replay")]
    assert replayed["received"] > 0 and replayed["latency_p99_us"] is None, replayed
    assert last["sim"]["replayed"] is False, "the live clock is shown, not the replay's"
    assert host.finish(up, 60) == 0, up.stderr()[-3000:]
    assert host.stop(player) == 0
    live = report(host, "live")
    assert live["metrics"]["collisions"] == 0 and live["metrics"]["unwarranted_emergencies"] == 0, live["metrics"]
    for hop in live["latency"]["hops"]:
        assert hop["p99_ms"] is None or hop["p99_ms"] < 1000, f"a replayed stamp taken as a live latency: {hop}"
    acc_log = (host.dir / "live" / "logs" / "slipstream-acc.log").read_text()
    assert 'from="sim@replay" following="sim"' in acc_log, acc_log[-2000:]


def test_a_recording_made_of_a_replay_plays_again(host):
    finished(host, "slipstream up --mode lockstep --duration 4 --record --report base --plain")
    recorder = host.start("slipstream -n replay record -o replayed.mcap")
    time.sleep(2)
    finished(host, "slipstream play base/run.mcap -n replay")
    assert host.stop(recorder) in (0, 1)
    publishers = {c.metadata.get("publisher") for c in channels(host.dir / "replayed.mcap")}
    assert "sim@replay" in publishers and "sim" not in publishers, publishers
    again = finished(host, "slipstream play replayed.mcap -n again --max")
    assert "played replayed.mcap" in again.stderr()


def fetch(host, port, path):
    """GET `path` of the view on `port`, from inside the host."""
    return host.run(f"python3 -c \"import urllib.request as u; print(u.urlopen("
                    f"'http://127.0.0.1:{port}{path}', timeout=5).read().decode())\"", 20)


def view_shows(host, command, port):
    """`view FILE` serves a page whose state has the recording's messages, once a page asks it
    to play (it waits for one)."""
    view = host.start(command)
    deadline = time.monotonic() + 60
    seen, asked = {}, False
    while time.monotonic() < deadline and not seen.get("vehicle/state"):
        time.sleep(0.5)
        try:
            asked = asked or fetch(host, port, "/replay?play=1").code == 0
            state = fetch(host, port, "/state")
        except AssertionError:
            continue
        if state.code == 0:
            seen = {k["key"]: k["received"] for k in json.loads(state.stdout())["top"]["keys"]}
    assert host.stop(view, signal.SIGINT) == 0, view.stderr()[-2000:]
    assert seen.get("vehicle/state"), f"`{command}` showed nothing: {seen}"
    assert "Invalid Key Expr" not in view.stderr(), view.stderr()[-2000:]


def test_every_kind_of_recording_plays_views_and_resimulates(host):
    kinds = {"plain": "--record", "viewable": "--record --viewable", "ros2": "--record --ros2"}
    for kind, flags in kinds.items():
        finished(host, f"slipstream up --mode lockstep --duration 5 {flags} --report {kind} --plain")
    for n, kind in enumerate(kinds):
        played = finished(host, f"slipstream play {kind}/run.mcap -n play-{kind} --max")
        assert "played" in played.stderr()
        view_shows(host, f"slipstream view {kind}/run.mcap --view-port {9100 + n}", 9100 + n)
        finished(host, f"slipstream up --from {kind}/run.mcap --report resim-{kind} --plain")
        assert report(host, f"resim-{kind}")["commands"]["missing"] == 0
    viewable_copies = [c for c in channels(host.dir / "viewable" / "run.mcap") if c.topic.startswith("/")]
    assert viewable_copies, "the viewable recording holds its copies"
    refused = finished(host, "slipstream play ros2/run.ros2.mcap", expect=1)
    assert "ROS 2 profile recording" in refused.stderr() and "run.mcap" in refused.stderr(), refused.stderr()


def drop_speed(source, target, every):
    """`source` with every `every`-th vehicle/speed message left out, the rest byte for byte:
    a recording that lost messages while it was made."""
    dropped = 0
    with open(source, "rb") as f, open(target, "wb") as out:
        writer = Writer(out, compression=CompressionType.NONE)
        writer.start()
        schemas, ids = {}, {}
        for schema, channel, message in make_reader(f).iter_messages():
            if schema is not None and schema.id not in schemas:
                schemas[schema.id] = writer.register_schema(schema.name, schema.encoding, schema.data)
            if channel.id not in ids:
                ids[channel.id] = writer.register_channel(channel.topic, channel.message_encoding,
                                                          schemas.get(channel.schema_id, 0), channel.metadata)
            if channel.topic == "vehicle/speed" and message.sequence % every == every // 2:
                dropped += 1
                continue
            writer.add_message(ids[channel.id], message.log_time, message.data, message.publish_time,
                               message.sequence)
        writer.finish()
    return dropped


def speed_gaps(path):
    """Sequence numbers missing from vehicle/speed, per publisher, as the file holds it."""
    last, gaps = {}, 0
    with open(path, "rb") as f:
        for _, channel, message in make_reader(f).iter_messages():
            if channel.topic == "vehicle/speed":
                key = channel.metadata.get("publisher")
                if key in last and message.sequence > last[key] + 1:
                    gaps += message.sequence - last[key] - 1
                last[key] = max(last.get(key, message.sequence), message.sequence)
    return gaps


def test_a_realtime_recording_that_lost_messages_resimulates_by_the_documented_rule(host):
    finished(host, "slipstream up --perception ground-truth --duration 8 --record --report rt --plain", expect=None)
    dropped = drop_speed(host.dir / "rt" / "run.mcap", host.dir / "lossy.mcap", 40)
    gaps = speed_gaps(host.dir / "lossy.mcap")
    assert dropped > 5 and gaps >= dropped
    resim = finished(host, "slipstream up --from lossy.mcap --report resim --plain")
    r = report(host, "resim")
    assert r["replay"]["lost_in_recording"]["vehicle/speed"] == gaps, r["replay"]
    assert 0 < r["replay"]["commands_without_input"] <= gaps and r["replay"]["gave_up"] is None, r["replay"]
    assert r["replay"]["steps_timed_out"] == 0, r["replay"]
    assert "the recording lacks" in resim.stdout() and f"vehicle/speed {gaps}" in resim.stdout(), resim.stdout()


STRANGER = textwrap.dedent("""
    import time, zenoh
    c = zenoh.Config()
    c.insert_json5("connect/endpoints", '["tcp/127.0.0.1:7447"]')
    c.insert_json5("scouting/multicast/enabled", "false")
    with zenoh.open(c) as s:
        for _ in range(400):
            s.put("stranger/noise", b"garbage")
            s.put("loop-2/vehicle/speed", b"garbage")
            time.sleep(0.05)
""")


def test_the_root_namespace_tools_see_the_root_loop_alone(host):
    (host.dir / "stranger.py").write_text(STRANGER)
    first = host.start("slipstream up --perception ground-truth --duration 25 --report one --plain")
    host.wait_for(first, "nodes alive: acc, sim, up", 60)
    second = host.start("slipstream up --perception ground-truth --duration 25 --report two --plain")
    host.wait_for(second, "in namespace loop-2", 60)
    stranger = host.start("python3 stranger.py")
    time.sleep(3)
    root = finished(host, "slipstream top --json --duration 3", timeout=30)
    keys = {k["key"] for line in root.stdout().splitlines() for k in json.loads(line)["keys"]}
    assert "vehicle/speed" in keys and not any(k.startswith(("loop-2/", "stranger/")) for k in keys), sorted(keys)
    every = finished(host, "slipstream top --all-namespaces --json --duration 3", timeout=30)
    keys = {k["key"] for line in every.stdout().splitlines() for k in json.loads(line)["keys"]}
    assert "loop-2/vehicle/speed" in keys and "vehicle/speed" in keys, sorted(keys)
    echoed = finished(host, "slipstream echo vehicle/speed --count 20", timeout=30)
    assert {json.loads(line)["key"] for line in echoed.stdout().splitlines()} == {"vehicle/speed"}
    recorder = host.run("slipstream record -o root.mcap --duration 3", 30)
    assert recorder.code in (0, 1), recorder.stderr()[-2000:]
    topics = {c.topic for c in channels(host.dir / "root.mcap")}
    assert "vehicle/speed" in topics and not any(t.startswith(("loop-2/", "stranger/")) for t in topics), topics
    assert host.finish(first, 60) == 0 and host.finish(second, 60) == 0
    assert host.stop(stranger, signal.SIGTERM) in (0, -signal.SIGTERM)
    assert not any(t["key"].startswith("loop-2/") for t in report(host, "one")["topics"])


DIES_SECOND = textwrap.dedent("""
    import os, pathlib, sys
    sys.path.insert(0, "clients/python/examples")
    import own_acc
    runs = pathlib.Path("runs.txt")
    n = int(runs.read_text()) if runs.exists() else 0
    runs.write_text(str(n + 1))
    if n == 1:
        steps = []
        def control(ego, ahead, settings):
            steps.append(1)
            if len(steps) == 50:
                print("boom: the second scenario kills me", file=sys.stderr, flush=True)
                os._exit(3)
            return own_acc.control(ego, ahead, settings)
        own_acc.run_controller(control)
    else:
        own_acc.run_controller(own_acc.control)
""")


def test_eval_acc_judges_the_scenarios_whose_controller_lived_and_names_the_one_that_died(host):
    (host.dir / "dies_second.py").write_text(DIES_SECOND)
    suite = finished(host, "slipstream eval acc --scenario steady-follow --scenario cut-in --perception ground-truth "
                           "--duration 6 -j 1 --controller 'python3 dies_second.py'", expect=1, timeout=300)
    table = suite.stdout()
    assert "| steady-follow |" in table and "pass |" in table, table
    row = next(line for line in table.splitlines() if line.startswith("| cut-in |"))
    assert row.count("|") == 17 and "did not finish" in row and "exit code 3" in row and "boom" in row, row
    assert "[2/2] cut-in (ground-truth perception): did not finish" in suite.stderr(), suite.stderr()[-2000:]
