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
