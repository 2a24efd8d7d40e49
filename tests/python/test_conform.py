"""`slipstream conform sim` passes slipstream-sim in every clock mode and the Python reference
simulator, fails naming the rule against simulators that break one rule each, gives a clear
verdict with nothing there or a publisher that is no simulator, and `up --sim external`
closes the loop (detector and ACC) around the Python reference simulator."""

import json
import subprocess
import sys
import time

import pytest
import zenoh
from conftest import ROOT, peer_config

REFERENCE = ROOT / "clients" / "python" / "examples" / "reference_sim.py"
BROKEN = ROOT / "tests" / "python" / "broken_sims.py"


def conform(slipstream_bin, endpoint, namespace, *args, timeout=60):
    """Runs `conform sim --json` against a simulator listening on `endpoint`; (exit code, verdicts by rule)."""
    out = subprocess.run(
        [slipstream_bin, "-e", endpoint, "-l", "tcp/127.0.0.1:0", "-n", namespace, "conform", "sim", "--json",
         "--duration", "2.5", *args],
        capture_output=True, text=True, timeout=timeout,
    )
    assert out.stdout, out.stderr
    report = json.loads(out.stdout)
    return out.returncode, {v["rule"]: v for v in report["verdicts"]}


class Running:
    """A simulator process, killed when the test leaves."""

    def __init__(self, argv, **popen):
        self.proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, **popen)
        time.sleep(0.5)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()


def python_sim(script, endpoint, namespace, *args):
    return Running([sys.executable, str(script), *args, "-l", endpoint, "-e", endpoint, "-n", namespace,
                    "--duration", "600"])


def hung_run_evidence(timeout, sim, report_dir):
    """What a run that did not end leaves to read: up's and the simulator's output, the nodes' logs."""
    def tail(text, n=3000):
        text = text.decode(errors="replace") if isinstance(text, bytes) else (text or "")
        return text[-n:]
    sim.proc.terminate()
    try:
        sim_out, sim_err = sim.proc.communicate(timeout=10)
    except subprocess.TimeoutExpired:
        sim.proc.kill()
        sim_out, sim_err = sim.proc.communicate()
    parts = [f"== up stderr\n{tail(timeout.stderr)}", f"== simulator stdout\n{tail(sim_out)}",
             f"== simulator stderr\n{tail(sim_err)}"]
    for log in sorted((report_dir / "logs").glob("*.log")):
        parts.append(f"== {log.name}\n{tail(log.read_text(errors='replace'), 2000)}")
    return "\n".join(parts)


def assert_keeps_the_contract(code, verdicts):
    failed = {r: v["detail"] for r, v in verdicts.items() if v["outcome"] == "FAIL"}
    assert code == 0 and not failed, failed


@pytest.mark.parametrize("mode", ["realtime", "fast", "lockstep"])
def test_slipstream_sim_keeps_the_contract_in_every_clock_mode(slipstream_bin, sim_bin, free_port, mode):
    endpoint, ns = f"tcp/127.0.0.1:{free_port}", f"conform-{mode}"
    # A long scenario on a straight road: nothing ends it while conform watches.
    argv = [sim_bin, "--scenario", "steady-follow", "--mode", mode, "--duration", "3000", "-l", endpoint, "-e",
            endpoint, "-n", ns]
    with Running(argv):
        code, verdicts = conform(slipstream_bin, endpoint, ns, *(["--lockstep"] if mode == "lockstep" else []))
    assert_keeps_the_contract(code, verdicts)
    assert verdicts["optional.objects"]["outcome"] == "PASS"
    assert verdicts["optional.sim_ego"]["outcome"] == "PASS"
    assert verdicts["optional.camera_narrow"]["outcome"] == "PASS"
    rule = "lockstep.answered" if mode == "lockstep" else "control.applied"
    assert verdicts[rule]["outcome"] == "PASS", verdicts[rule]


@pytest.mark.parametrize("mode", ["realtime", "lockstep"])
def test_the_python_reference_simulator_keeps_the_contract(slipstream_bin, free_port, mode):
    endpoint, ns = f"tcp/127.0.0.1:{free_port}", f"conform-ref-{mode}"
    with python_sim(REFERENCE, endpoint, ns, "--mode", mode):
        code, verdicts = conform(slipstream_bin, endpoint, ns, *(["--lockstep"] if mode == "lockstep" else []))
    assert_keeps_the_contract(code, verdicts)
    assert verdicts["optional.camera_narrow"]["outcome"] == "SKIP"


@pytest.mark.parametrize("broken, mode, rule, words", [
    ("NoCamera", "realtime", "required.camera_front", "nothing on"),
    ("SpeedAt10Hz", "realtime", "rate.vehicle_speed", "10.0 Hz"),
    ("StampsBackwards", "realtime", "stamps.monotonic", "went back"),
    ("InfoNotLatched", "realtime", "camera_info.late_subscriber", "never got"),
    ("IgnoresControl", "realtime", "control.applied", "never showed"),
    ("NoLockstepWait", "lockstep", "lockstep.answered", "without waiting"),
])
def test_a_simulator_breaking_a_rule_fails_it_by_name(slipstream_bin, free_port, broken, mode, rule, words):
    endpoint, ns = f"tcp/127.0.0.1:{free_port}", f"broken-{broken}"
    with python_sim(BROKEN, endpoint, ns, broken, "--mode", mode):
        code, verdicts = conform(slipstream_bin, endpoint, ns, *(["--lockstep"] if mode == "lockstep" else []))
    assert code == 1
    assert verdicts[rule]["outcome"] == "FAIL", verdicts[rule]
    assert words in verdicts[rule]["detail"], verdicts[rule]


def test_nothing_there_or_a_publisher_that_is_no_simulator_is_a_clear_verdict(slipstream_bin, free_port):
    endpoint = f"tcp/127.0.0.1:{free_port}"
    started = time.monotonic()
    code, verdicts = conform(slipstream_bin, endpoint, "nobody", "--wait", "1")
    assert code == 1 and time.monotonic() - started < 30
    assert "nothing on nobody/vehicle/speed in" in verdicts["required.vehicle_speed"]["detail"]

    conf = peer_config(endpoint)
    conf.insert_json5("listen/endpoints", f'["{endpoint}"]')
    with zenoh.open(conf) as session:
        pub = session.declare_publisher("impostor/vehicle/speed")
        proc = subprocess.Popen(
            [slipstream_bin, "-e", endpoint, "-l", "tcp/127.0.0.1:0", "-n", "impostor", "conform", "sim", "--json",
             "--duration", "1", "--wait", "5"], stdout=subprocess.PIPE, text=True)
        deadline = time.monotonic() + 30
        while proc.poll() is None and time.monotonic() < deadline:
            pub.put(b"not a slipstream message")
            time.sleep(0.02)
        out, _ = proc.communicate(timeout=30)
    verdicts = {v["rule"]: v for v in json.loads(out)["verdicts"]}
    assert proc.returncode == 1
    assert "do not decode" in verdicts["required.vehicle_speed"]["detail"], verdicts["required.vehicle_speed"]


def test_up_closes_the_loop_around_the_python_reference_simulator(slipstream_bin, free_port, tmp_path):
    endpoint, ns = f"tcp/127.0.0.1:{free_port}", "external"
    report_dir = tmp_path / "report"
    sim = Running([sys.executable, str(REFERENCE), "--mode", "lockstep", "--duration", "30", "-e", endpoint,
                   "-n", ns])
    with sim:
        argv = [slipstream_bin, "-l", endpoint, "-n", ns, "up", "--sim", "external", "--mode", "lockstep", "--plain",
                "--report", str(report_dir)]
        try:
            up = subprocess.run(argv, capture_output=True, text=True, timeout=240)
        except subprocess.TimeoutExpired as e:
            pytest.fail(f"up did not end in 240 s\n{hung_run_evidence(e, sim, report_dir)}")
        sim_out, _ = sim.proc.communicate(timeout=30)
    assert up.returncode == 0, up.stderr[-3000:]
    report = json.loads((report_dir / "report.json").read_text())
    assert report["sim"] == "external" and report["ground_truth"], report["ended"]
    assert report["ended"] == "duration reached" and report["collisions"] == 0
    assert report["sim_time_s"] > 29
    # The ACC followed the simulator's lead through the camera: the detector saw it, the ACC
    # slowed behind it and answered every step.
    m = report["metrics"]
    assert m["min_gap_m"] > 10 and m["max_decel_mps2"] < 5, m
    rows = {r["key"]: r for r in report["topics"]}
    assert rows[f"{ns}/perception/objects"]["from"] == "detect", rows.keys()
    assert rows[f"{ns}/vehicle/control"]["from"] == "acc"
    assert "# 3000 steps" in sim_out, sim_out
