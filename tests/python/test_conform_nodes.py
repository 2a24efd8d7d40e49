"""`slipstream conform controller` and `conform detector`: ours and the Python examples keep the
node contract; deliberately broken controllers fail it, each naming the rule it breaks (an answer
naming the wrong step, stamped with the wall clock, no liveliness token, no answer at all)."""

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import ROOT

PY = sys.executable
ENV = dict(os.environ, PATH=f"{Path(PY).parent}{os.pathsep}{os.environ['PATH']}")


def conform(slipstream_bin, role, command):
    done = subprocess.run([slipstream_bin, "conform", role, "--command", command, "--json"], cwd=ROOT,
                          capture_output=True, text=True, timeout=120, env=ENV)
    assert done.stdout, done.stderr[-3000:]
    report = json.loads(done.stdout)
    assert done.returncode == (0 if report["pass"] else 1)
    return report


def failed(report):
    return sorted(v["rule"] for v in report["verdicts"] if v["outcome"] == "FAIL")


@pytest.mark.parametrize("role,command", [
    ("controller", f"{PY} clients/python/examples/own_acc.py"),
    ("controller", "BIN/slipstream-acc --lockstep --perception ground-truth"),
    ("controller", "BIN/own-controller"),
    ("detector", f"{PY} clients/python/examples/own_detect.py"),
    ("detector", "BIN/slipstream-detect"),
    ("detector", "BIN/own-detector"),
])
def test_ours_and_the_examples_keep_the_node_contract(slipstream_bin, role, command):
    report = conform(slipstream_bin, role, command.replace("BIN", str(Path(slipstream_bin).parent)))
    assert report["pass"] and report["subject"] == role, report["verdicts"]
    assert len(report["verdicts"]) >= 5


@pytest.mark.parametrize("mode,rule", [
    ("wrong-step", "answers_step"),
    ("wall-stamp", "stamp_copied"),
    ("no-token", "token"),
    ("silent", "every_step_answered"),
])
def test_a_broken_controller_fails_naming_the_rule(slipstream_bin, mode, rule):
    report = conform(slipstream_bin, "controller", f"{PY} tests/python/bad_controllers.py {mode}")
    assert not report["pass"] and rule in failed(report), report["verdicts"]


def test_a_controller_whose_answers_never_decode_passes_no_rule_on_zero_evidence(slipstream_bin):
    report = conform(slipstream_bin, "controller", f"{PY} tests/python/bad_controllers.py garbage")
    verdicts = {v["rule"]: v for v in report["verdicts"]}
    for rule in ("answers_step", "stamp_copied", "attachment", "pedals"):
        assert verdicts[rule]["outcome"] == "FAIL", verdicts[rule]
        assert "no decodable answer on vehicle/control" in verdicts[rule]["detail"], verdicts[rule]
        assert "payloads did not decode" in verdicts[rule]["detail"], verdicts[rule]


def test_a_controller_that_crashes_is_named_with_its_exit_and_last_words(slipstream_bin):
    report = conform(slipstream_bin, "controller", f"{PY} tests/python/bad_controllers.py crash")
    died = next(v for v in report["verdicts"] if v["rule"] == "kept_running")
    assert died["outcome"] == "FAIL" and "exit code 1" in died["detail"], died
    assert "the model diverged" in died["detail"], died


@pytest.mark.parametrize("mode,rule", [("example", None), ("wall-stamp", "stamp_copied")])
def test_a_controller_already_running_is_checked_where_it_runs(slipstream_bin, free_port, mode, rule):
    """No --command: the node started by hand (as on another PC) is awaited by its token in the
    namespace given and judged on the same rules; it keeps running after the check."""
    endpoint, ns = f"tcp/127.0.0.1:{free_port}", f"byhand-{mode}"
    node = [PY, "tests/python/bad_controllers.py", mode] if rule else [PY, "clients/python/examples/own_acc.py"]
    running = subprocess.Popen([*node, "-n", ns, "-l", endpoint, "--perception", "ground-truth", "--clock", "lockstep"],
                               cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=ENV)
    try:
        done = subprocess.run([slipstream_bin, "-n", ns, "-e", endpoint, "conform", "controller", "--json"], cwd=ROOT,
                              capture_output=True, text=True, timeout=120, env=ENV)
        assert running.poll() is None, "the check stopped the user's node"
    finally:
        running.terminate()
        running.communicate(timeout=30)
    assert done.stdout, done.stderr[-3000:]
    report = json.loads(done.stdout)
    assert report["namespace"] == ns and done.returncode == (1 if rule else 0), report
    assert (rule in failed(report)) if rule else failed(report) == [], report["verdicts"]
    assert f"its token nodes/acc in namespace `{ns}`" in done.stderr
