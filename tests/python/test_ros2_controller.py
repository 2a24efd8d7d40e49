"""A ROS 2 controller as a node of a loop file (`controller: { command, ros2: true }`): the loop
runs `slipstream ros2 --control` beside it as `acc`, and the controller, a stand-in on
zenoh-ros2-sdk (tests/python/ros2_controller.py: rmw_zenoh's keys, tokens and CDR in code we did
not write), drives the ego in `up` and in `eval acc` in lockstep, each odometry answered by a
command carrying its stamp: the same figures twice. One that stamps its commands with another
time answers nothing: the bridge refuses and says why, the run ends at the step left
unanswered."""

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import ROOT

pytest.importorskip("zenoh_ros2_sdk")

PY = sys.executable
ENV = dict(os.environ, PATH=f"{Path(PY).parent}{os.pathsep}{os.environ['PATH']}")


def msgs_dir(slipstream_bin, tmp_path):
    """The message definitions in zenoh-ros2-sdk's registry layout, from `ros2 --list --types`."""
    rows = json.loads(subprocess.run([slipstream_bin, "ros2", "--list", "--types", "--json"], capture_output=True,
                                     text=True, check=True, cwd=ROOT).stdout)
    root = tmp_path / "msgs"
    for row in rows:
        package, _, name = row["type"].split("/")
        path = root / package / "msg" / f"{name}.msg"
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(row["definition"].split("\n====")[0])
    return root


def loop_file(slipstream_bin, tmp_path, *flags):
    msgs = msgs_dir(slipstream_bin, tmp_path)
    path = tmp_path / "ros.json5"
    command = " ".join([PY, str(ROOT / "tests" / "python" / "ros2_controller.py"), "--msgs", str(msgs), *flags])
    path.write_text(f'{{ controller: {{ command: "{command}", ros2: true }} }}')
    return path


def slipstream(slipstream_bin, *args, timeout=300):
    return subprocess.run([slipstream_bin, *args], cwd=ROOT, capture_output=True, text=True, timeout=timeout, env=ENV)


def test_a_ros2_controller_of_a_loop_file_drives_up_in_lockstep(slipstream_bin, free_port, tmp_path):
    path = loop_file(slipstream_bin, tmp_path, "--speed", "20")
    done = slipstream(slipstream_bin, "-l", f"tcp/127.0.0.1:{free_port}", "-n", "rosloop", "up", "--loop", str(path),
                      "--scenario",
                      "open-road", "--mode", "lockstep", "--perception", "ground-truth", "--duration", "8", "--plain",
                      "--report", str(tmp_path / "run"), timeout=120)
    assert done.returncode in (0, 1), done.stderr[-3000:]
    report = json.loads((tmp_path / "run" / "report.json").read_text())
    ends = {n["node"]: n for n in report["nodes"]}
    assert ends["controller"]["exit_code"] == 0 and ends["ros2-bridge"]["exit_code"] == 0, ends
    assert report["own"]["controller"]["ros2"] and report["ended"].startswith("duration"), report["ended"]
    logs = tmp_path / "run" / "logs"
    answered = int((logs / "controller.out").read_text().split("my_acc: ")[1].split()[0])
    commands = json.loads((logs / "ros2-bridge.json").read_text())["commands"]
    # Every state answered through the bridge, none refused; judged like any controller.
    assert answered >= 790 and commands["applied"] == answered and commands["refused"] == 0, (answered, commands)
    assert report["metrics"]["collisions"] == 0 and report["metrics"]["duration_s"] > 7.5, report["metrics"]


def test_a_ros2_controller_is_judged_by_eval_the_same_twice(slipstream_bin, tmp_path):
    path = loop_file(slipstream_bin, tmp_path)
    runs = []
    for _ in range(2):
        done = slipstream(slipstream_bin, "eval", "acc", "--scenario", "steady-follow", "--loop", str(path),
                          "--perception", "ground-truth", "--json")
        assert done.stdout, done.stderr[-3000:]
        runs.append(json.loads(done.stdout)["results"][0])
    assert runs[0]["metrics"] == runs[1]["metrics"] and runs[0]["lockstep_timeouts"] == 0, runs[0]
    assert runs[0]["metrics"]["collisions"] == 0 and runs[0]["metrics"]["duration_s"] > 50, runs[0]["metrics"]


def test_a_ros2_controller_stamping_another_time_answers_nothing_and_is_told_why(slipstream_bin, tmp_path):
    path = loop_file(slipstream_bin, tmp_path, "--stamp", "zero")
    done = slipstream(slipstream_bin, "eval", "acc", "--scenario", "steady-follow", "--loop", str(path),
                      "--perception", "ground-truth", timeout=180)
    assert done.returncode != 0 and "lockstep timeout" in done.stderr, done.stderr[-3000:]
    logs = Path(done.stderr.split("node logs in ")[1].split(")")[0])
    said = (logs / "ros2-bridge.log").read_text()
    assert "the time of no state awaiting an answer (copy the odometry's header.stamp)" in said, said[-2000:]
