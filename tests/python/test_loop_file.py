"""The loop file (`--loop FILE`, config/loop.json5): a Python controller and a node in no role
of ours started, awaited (one by its token, one by its first sample) and named in `up`'s report;
a controller that crashes started again per its restart policy, the run finished and the
restart and the missed steps counted; a controller started elsewhere awaited and driving in
lockstep, and refused by eval; a sweep over a loop file names it by content; a bad file
refused naming the file, the key and the fix, before anything starts."""

import hashlib
import json
import os
import subprocess
import sys
from pathlib import Path

from conftest import ROOT

PYTHON = sys.executable


# `python3` in a loop file is the one on PATH: this interpreter's, with the client installed.
ENV = dict(os.environ, PATH=f"{Path(PYTHON).parent}{os.pathsep}{os.environ['PATH']}")


def slipstream(slipstream_bin, *args, timeout=300):
    return subprocess.run([slipstream_bin, *args], cwd=ROOT, capture_output=True, text=True, timeout=timeout,
                          env=ENV)


def loop_file(tmp_path, text):
    path = tmp_path / "mine.json5"
    path.write_text(text)
    return path


def test_up_runs_a_python_controller_and_a_monitor_of_the_loop_file(slipstream_bin, free_port, tmp_path):
    path = loop_file(tmp_path, f"""{{
        controller: {{ command: "{PYTHON} {ROOT}/clients/python/examples/own_acc.py" }},
        others: [{{ name: "monitor", command: ["{PYTHON}", "{ROOT}/tests/python/loop_monitor.py"],
                    ready: {{ sample: "monitor/heartbeat" }}, log: "monitor/stderr.log" }}],
    }}""")
    done = slipstream(slipstream_bin, "-l", f"tcp/127.0.0.1:{free_port}", "up", "--loop", str(path),
                      "--scenario", "steady-follow", "--mode", "lockstep", "--perception", "ground-truth",
                      "--duration", "5", "--plain", "--report", str(tmp_path / "up"), timeout=120)
    assert done.returncode == 0, done.stderr[-3000:]
    report = json.loads((tmp_path / "up" / "report.json").read_text())
    ends = {n["node"]: n for n in report["nodes"]}
    assert ends["controller"]["exit_code"] == 0 and ends["monitor"]["exit_code"] == 0, ends
    assert ends["monitor"]["log"].endswith("logs/monitor/stderr.log"), ends["monitor"]
    # The monitor was up before the simulator's first step: it saw every status of the run.
    said = (tmp_path / "up" / "logs" / "monitor.out").read_text()
    assert int(said.split("monitor: ")[1].split()[0]) >= 90, said
    own = report["own"]
    assert own["others"][0]["name"] == "monitor" and own["controller"]["role"] == "controller", own
    assert own["loop_file"]["sha256"] == hashlib.sha256(path.read_bytes()).hexdigest()


def test_a_controller_started_elsewhere_is_awaited_and_closes_the_loop_in_lockstep(slipstream_bin, free_port,
                                                                                   tmp_path):
    path = loop_file(tmp_path, "{ controller: { elsewhere: true, ready: { timeout_s: 60 } } }")
    endpoint, ns = f"tcp/127.0.0.1:{free_port}", "faraway"
    up = subprocess.Popen([slipstream_bin, "-l", endpoint, "-n", ns, "up", "--loop", str(path), "--scenario",
                           "steady-follow", "--mode", "lockstep", "--perception", "ground-truth", "--duration", "5",
                           "--plain", "--report", str(tmp_path / "run")], cwd=ROOT, stdout=subprocess.PIPE,
                          stderr=subprocess.PIPE, text=True, env=ENV)
    # The user's node, started by hand after `up` (as on another PC): the role's name, the namespace.
    own = subprocess.Popen([str(Path(slipstream_bin).parent / "own-controller"), "-e", endpoint, "-n", ns,
                            "--name", "acc", "--clock", "lockstep", "--perception", "ground-truth"],
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        out, err = up.communicate(timeout=120)
    finally:
        own.terminate()
        sent, _ = own.communicate(timeout=30)
    assert up.returncode == 0, err[-3000:]
    assert "waiting up to 60 s for the controller started elsewhere: its token nodes/acc in namespace `faraway`" in err
    report = json.loads((tmp_path / "run" / "report.json").read_text())
    assert report["own"]["controller"]["elsewhere"] and report["own"]["controller"]["command"] == [], report["own"]
    assert report["ended"].startswith("duration") and report["collisions"] == 0, report["ended"]
    answered = int(sent.split(": ")[1].split()[0])
    assert answered >= 499, sent
    # eval runs every loop in a namespace of its own: nobody can be waiting there.
    refused = slipstream(slipstream_bin, "eval", "acc", "--scenario", "cut-in", "--loop", str(path), timeout=60)
    assert refused.returncode != 0 and "key `controller.elsewhere`" in refused.stderr, refused.stderr[-2000:]


def test_a_controller_that_crashes_is_started_again_per_its_policy_and_counted(slipstream_bin, tmp_path):
    mark = tmp_path / "crashed"
    path = loop_file(tmp_path, f"""{{
        controller: {{ command: "{PYTHON} {ROOT}/tests/python/bad_controllers.py crash-once {mark}",
                       restart: {{ policy: "on-failure", limit: 2, backoff_s: 0.2 }} }},
    }}""")
    done = slipstream(slipstream_bin, "eval", "acc", "--loop", str(path), "--scenario", "cut-in",
                      "--perception", "ground-truth", "--json", "--timeout", "120", timeout=180)
    assert done.stdout, done.stderr[-3000:]
    run = json.loads(done.stdout)["results"][0]
    assert mark.exists() and run["restarts"] == {"controller": 1}, run.get("restarts")
    # The steps the controller missed took the simulator's timeout policy; the run went on.
    assert run["lockstep_timeouts"] >= 1 and run["metrics"]["duration_s"] > 30, run
    assert done.returncode == 1, done.stderr[-2000:]


def test_a_sweep_over_a_loop_file_names_the_file_by_content(slipstream_bin, tmp_path):
    example = ROOT / "clients" / "python" / "examples" / "own_loop.json5"
    done = slipstream(slipstream_bin, "eval", "sweep", "--count", "2", "--perception", "ground-truth",
                      "--loop", str(example), "--report", str(tmp_path / "sweep"))
    assert done.returncode in (0, 1), done.stderr[-3000:]
    report = json.loads((tmp_path / "sweep" / "sweep.json").read_text())
    assert len(report["runs"]) == 2 and all(r["result"] for r in report["runs"]), report["runs"]
    own = report["own"]
    assert own["loop_file"]["sha256"] == hashlib.sha256(example.read_bytes()).hexdigest()
    assert own["controller"]["run"]["restart"]["policy"] == "on-failure", own


def test_a_bad_loop_file_is_refused_naming_file_key_and_fix(slipstream_bin, tmp_path):
    path = loop_file(tmp_path, "{ controller: { command: 'python3 acc.py' }, others: [{ name: 'acc', command: 'sh' }] }")
    (tmp_path / "acc.py").write_text("")
    done = slipstream(slipstream_bin, "up", "--loop", str(path), "--report", str(tmp_path / "up"), timeout=60)
    assert done.returncode == 1 and not (tmp_path / "up").exists(), (done.returncode, done.stderr)
    said = done.stderr
    assert f"{path}: key `others[0].name`" in said and "(fix: " in said and "under `controller`" in said, said


def test_a_simulator_of_your_own_is_started_from_the_loop_file_and_the_loop_closes_around_it(slipstream_bin,
                                                                                               free_port, tmp_path):
    sim = f"{PYTHON} {ROOT}/clients/python/examples/reference_sim.py --duration 6"
    path = loop_file(tmp_path, f'{{ simulator: {{ command: "{sim}" }} }}')
    done = slipstream(slipstream_bin, "-l", f"tcp/127.0.0.1:{free_port}", "-n", "own-sim", "up", "--loop", str(path),
                      "--mode", "lockstep", "--perception", "ground-truth", "--plain", "--report",
                      str(tmp_path / "run"), timeout=120)
    assert done.returncode == 0, done.stderr[-3000:]
    report = json.loads((tmp_path / "run" / "report.json").read_text())
    assert report["sim"] == "external" and report["own"]["simulator"]["role"] == "simulator", report["own"]
    ends = {n["node"]: n for n in report["nodes"]}
    # It ran the loop's clock (SLIPSTREAM_CLOCK) to its own end and closed by itself.
    assert ends["simulator"]["exit_code"] == 0 and not ends["simulator"]["died"], ends
    said = (tmp_path / "run" / "logs" / "simulator.out").read_text()
    assert "# reference simulator: lockstep, 6 s" in said and "# 600 steps" in said, said
    assert report["ended"].startswith("duration") and report["metrics"]["collisions"] == 0, report["ended"]
    # eval judges on slipstream's scenarios: the file is refused by its key.
    refused = slipstream(slipstream_bin, "eval", "acc", "--scenario", "cut-in", "--loop", str(path), timeout=60)
    assert refused.returncode != 0 and "key `simulator.command`" in refused.stderr, refused.stderr[-2000:]


def test_a_simulator_of_your_own_that_fails_at_start_is_named_at_once(slipstream_bin, free_port, tmp_path):
    sim = f"{PYTHON} {ROOT}/clients/python/examples/reference_sim.py --physics-hz 7"
    path = loop_file(tmp_path, f'{{ simulator: {{ command: "{sim}" }} }}')
    done = slipstream(slipstream_bin, "-l", f"tcp/127.0.0.1:{free_port}", "-n", "own-sim-fails", "up", "--loop",
                      str(path), "--plain", "--report", str(tmp_path / "run"), timeout=60)
    assert done.returncode == 1, done.stderr[-3000:]
    assert "simulator ended before its first message: --camera-hz must divide --physics-hz" in done.stderr, \
        done.stderr[-2000:]
