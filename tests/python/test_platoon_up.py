"""`slipstream up` with several controlled vehicles when one car's node fails: the car is
named, the run ends with exit code 1, and the report still judges every car (docs/simulator.md,
"Several controlled vehicles")."""

import json
import os
import signal
import subprocess
import time

from conftest import ROOT


def pid_of(pattern):
    found = subprocess.run(["pgrep", "-f", pattern], capture_output=True, text=True).stdout.split()
    return int(found[0]) if found else None


def test_a_cars_acc_killed_mid_run_is_named_and_the_other_cars_are_still_judged(slipstream_bin, free_port, tmp_path):
    ns = f"platoon-kill-{os.getpid()}"
    report = tmp_path / "run"
    up = subprocess.Popen(
        [slipstream_bin, "-n", ns, "-l", f"tcp/127.0.0.1:{free_port}", "up", "--scenario", "platoon-8",
         "--perception", "ground-truth", "--mode", "lockstep", "--duration", "60", "--report", str(report),
         "--plain"], cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        # The simulator starts after every car's ACC is ready: then car 3's is killed.
        deadline = time.monotonic() + 60
        victim = None
        while victim is None:
            assert up.poll() is None and time.monotonic() < deadline, "the platoon never started"
            if (report / "logs" / "slipstream-sim.log").exists():
                time.sleep(2)
                victim = pid_of(f"slipstream-acc .*-n {ns}/car3 ")
            time.sleep(0.2)
        os.kill(victim, signal.SIGKILL)
        out, err = up.communicate(timeout=60)
    finally:
        if up.poll() is None:
            up.kill()
    assert up.returncode == 1, err[-3000:]
    assert "car3-acc ended before the run was over" in err, err[-3000:]
    r = json.loads((report / "report.json").read_text())
    died = {n["node"] for n in r["nodes"] if n["died"]}
    assert died == {"car3-acc"}, r["nodes"]
    assert [e["namespace"] for e in r["egos"]] == [f"car{k}" for k in range(1, 9)]
    # Every car drove until the run ended, and each is judged on what it recorded.
    assert all(e["metrics"] and e["metrics"]["duration_s"] > 1 for e in r["egos"]), r["egos"]
    assert "car3" in out and "collisions between controlled vehicles" in out, out


def test_eval_acc_judges_every_car_of_a_platoon_against_the_aims(slipstream_bin):
    done = subprocess.run([slipstream_bin, "eval", "acc", "--scenario", "platoon-8-hard-brake", "--perception",
                           "ground-truth", "--duration", "30", "--json"], cwd=ROOT, capture_output=True, text=True,
                          timeout=300)
    report = json.loads(done.stdout)
    run = report["results"][0]
    assert [e["namespace"] for e in run["egos"]] == [f"car{k}" for k in range(1, 9)], run["egos"]
    for e in run["egos"]:
        assert e["metrics"]["collisions"] == 0 and e["lockstep_timeouts"] == 0, e
    # The leader's hard brake reaches the first car hardest; the string passes on it or fails by it.
    decels = [e["metrics"]["max_decel_mps2"] for e in run["egos"]]
    assert decels[0] > decels[-1], decels
    assert report["pass"] == all(e["metrics"]["pass"] for e in run["egos"]) == (done.returncode == 0), done.stderr
    table = subprocess.run([slipstream_bin, "eval", "acc", "--scenario", "platoon-8-hard-brake", "--perception",
                            "ground-truth", "--duration", "30"], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert all(f"| platoon-8-hard-brake car{k} |" in table.stdout for k in range(1, 9)), table.stdout
