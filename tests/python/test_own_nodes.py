"""A controller of the user's own, in Python on the SDK (clients/python/examples/own_acc.py),
in the place of slipstream-acc: run by `up` and `eval`, judged like ours, the same twice in
lockstep, named in the report by its command and its file's content; a node that cannot start
is named with what it did."""

import hashlib
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from conftest import ROOT

OWN_ACC = "clients/python/examples/own_acc.py"
CONTROLLER = f"{sys.executable} {OWN_ACC}"


def slipstream(slipstream_bin, *args, timeout=300):
    return subprocess.run([slipstream_bin, *args], cwd=ROOT, capture_output=True, text=True, timeout=timeout)


def eval_acc(slipstream_bin, scenario, perception):
    done = slipstream(slipstream_bin, "eval", "acc", "--scenario", scenario, "--perception", perception,
                      "--json", "--controller", CONTROLLER)
    assert done.stdout, done.stderr[-3000:]
    return done.returncode, json.loads(done.stdout)


@pytest.mark.parametrize("perception", ["ground-truth", "camera"])
def test_a_python_controller_is_judged_like_ours_and_the_same_twice_in_lockstep(slipstream_bin, perception):
    (code, first), (_, second) = (eval_acc(slipstream_bin, "cut-in", perception) for _ in range(2))
    run = first["results"][0]
    assert run["lockstep_timeouts"] == 0 and run["metrics"]["collisions"] == 0, run
    assert run["metrics"]["duration_s"] > 10, run["metrics"]
    assert code == (0 if first["pass"] else 1)
    # Lockstep: the same answers, so the same figures, to the last digit.
    assert first["results"][0]["metrics"] == second["results"][0]["metrics"]
    controller = first["own"]["controller"]
    assert controller["command"] == [sys.executable, OWN_ACC]
    script = next(f for f in controller["files"] if f["path"] == OWN_ACC)
    assert script["sha256"] == hashlib.sha256((ROOT / OWN_ACC).read_bytes()).hexdigest()
    assert first["own"]["detector"] is None


def test_a_rust_controller_on_the_contract_sdk_is_judged_and_the_same_twice_in_lockstep(slipstream_bin):
    # examples/own-controller: one function on slipstream_contract::node::controller, which
    # answers lockstep, copies stamps and awaits the frame's objects for it.
    binary = str(Path(slipstream_bin).parent / "own-controller")
    runs = [slipstream(slipstream_bin, "eval", "acc", "--scenario", "cut-in", "--perception", "camera", "--json",
                       "--controller", binary) for _ in range(2)]
    first, second = (json.loads(r.stdout) for r in runs)
    run = first["results"][0]
    assert run["lockstep_timeouts"] == 0 and run["metrics"]["collisions"] == 0, run
    assert run["metrics"]["duration_s"] > 30 and run["metrics"]["min_gap_m"] > 2, run["metrics"]
    assert first["results"][0]["metrics"] == second["results"][0]["metrics"]
    assert first["own"]["controller"]["files"][0]["sha256"] == hashlib.sha256(Path(binary).read_bytes()).hexdigest()


def test_bench_nodes_runs_the_same_sweep_with_ours_and_both_sdk_examples(slipstream_bin):
    # The bench's python3 must be the one that imports zenoh: this interpreter's.
    env = dict(os.environ, PATH=f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}")
    done = subprocess.run([slipstream_bin, "bench", "nodes", "--quick", "--json"], cwd=ROOT, capture_output=True,
                          text=True, timeout=600, env=env)
    assert done.returncode == 0, done.stderr[-3000:]
    rows = json.loads(done.stdout)["nodes"]
    assert [r["controller"] for r in rows] == ["slipstream-acc", "Python SDK (own_acc.py)", "Rust SDK (own-controller)"]
    # The same seed: each drove the same scenarios, step for step (none ended a run early).
    assert len({r["steps"] for r in rows}) == 1 and rows[0]["steps"] > 1000, rows
    ours = rows[0]
    for r in rows:
        assert r["sweep_wall_s"] > 0 and r["awaited_per_step_us"] > 0, r
        assert abs(r["wall_vs_ours"] - r["sweep_wall_s"] / ours["sweep_wall_s"]) < 1e-9, r
        assert abs(r["added_per_step_us"] - (r["awaited_per_step_us"] - ours["awaited_per_step_us"])) < 1e-6, r
    assert rows[1]["command"].endswith("clients/python/examples/own_acc.py") and ours["command"] is None


def test_a_small_sweep_runs_a_python_controller_and_names_it(slipstream_bin, tmp_path):
    done = slipstream(slipstream_bin, "eval", "sweep", "--count", "4", "--perception", "ground-truth",
                      "--controller", CONTROLLER, "--report", str(tmp_path / "mine"))
    assert done.returncode in (0, 1), done.stderr[-3000:]
    report = json.loads((tmp_path / "mine" / "sweep.json").read_text())
    assert len(report["runs"]) == 4 and all(r["result"] for r in report["runs"]), report["runs"]
    assert report["own"]["controller"]["command"] == [sys.executable, OWN_ACC]


def test_up_closes_the_loop_around_a_python_controller(slipstream_bin, free_port, tmp_path):
    done = slipstream(slipstream_bin, "-l", f"tcp/127.0.0.1:{free_port}", "up", "--scenario", "steady-follow",
                      "--mode", "lockstep", "--perception", "ground-truth", "--duration", "5", "--plain",
                      "--report", str(tmp_path), "--controller", CONTROLLER, timeout=120)
    assert done.returncode == 0, done.stderr[-3000:]
    report = json.loads((tmp_path / "report.json").read_text())
    assert report["ended"] == "duration of 5 s reached" and report["metrics"]["duration_s"] > 4.9, report["ended"]
    assert any(n["node"] == "controller" and n["exit_code"] == 0 for n in report["nodes"]), report["nodes"]
    # One answer per state at 100 Hz, counted by the SDK as it stopped.
    assert "# acc: 500 commands" in (tmp_path / "logs" / "controller.out").read_text()


def test_a_controller_that_exits_at_start_is_named_with_its_exit(slipstream_bin):
    done = slipstream(slipstream_bin, "eval", "acc", "--scenario", "cut-in", "--perception", "ground-truth",
                      "--controller", f"{sys.executable} -c 'import sys; print(\"no model\", file=sys.stderr); sys.exit(3)'",
                      timeout=120)
    assert done.returncode != 0
    assert "controller" in done.stderr and "exited at start" in done.stderr, done.stderr[-2000:]
    assert "exit status: 3" in done.stderr, done.stderr[-2000:]


def test_a_controller_command_that_cannot_run_is_refused_before_anything_starts(slipstream_bin):
    done = slipstream(slipstream_bin, "eval", "acc", "--scenario", "cut-in", "--controller", "no-such-acc --fast",
                      timeout=60)
    assert done.returncode == 2 or done.returncode == 1
    assert "--controller" in done.stderr and "neither a file nor a program on PATH" in done.stderr, done.stderr


BAD = f"{sys.executable} tests/python/bad_controllers.py"


def test_a_controller_that_never_answers_ends_its_run_at_the_first_step_left_unanswered(slipstream_bin):
    started = time.monotonic()
    done = slipstream(slipstream_bin, "eval", "acc", "--scenario", "cut-in", "--perception", "ground-truth",
                      "--controller", f"{BAD} silent", timeout=120)
    assert done.returncode == 1
    assert "lockstep timeout at step 0 waiting for acc" in done.stderr, done.stderr[-2000:]
    # One step's timeout (2 s), not one per step of the scenario.
    assert time.monotonic() - started < 60


def test_a_sweep_over_a_controller_that_crashes_finishes_with_its_runs_marked(slipstream_bin, tmp_path):
    done = slipstream(slipstream_bin, "eval", "sweep", "--count", "2", "--perception", "ground-truth",
                      "--controller", f"{BAD} crash", "--report", str(tmp_path / "bad"))
    assert done.returncode == 1, done.stderr[-3000:]
    runs = json.loads((tmp_path / "bad" / "sweep.json").read_text())["runs"]
    assert len(runs) == 2 and all(r.get("result") is None for r in runs), runs
    assert all("controller ended before the run was over (exit code 1): RuntimeError: the model diverged"
               in r["error"] for r in runs), [r["error"] for r in runs]
