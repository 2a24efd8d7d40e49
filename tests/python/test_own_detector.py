"""A detector of the user's own, in Python on the SDK (clients/python/examples/own_detect.py,
numpy and OpenCV), in slipstream-detect's place: scored by `eval detect` on the same frames and
ground truth as ours and named in the report; closing the loop in `eval acc` in lockstep, the
same twice; a detector that dies is named with its last words."""

import json
import os
import subprocess
import sys
from pathlib import Path

from conftest import ROOT

OWN_DETECT = "clients/python/examples/own_detect.py"
DETECTOR = f"{sys.executable} {OWN_DETECT}"
ENV = dict(os.environ, PATH=f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}")


def slipstream(slipstream_bin, *args, timeout=300):
    return subprocess.run([slipstream_bin, *args], cwd=ROOT, capture_output=True, text=True, timeout=timeout,
                          env=ENV)


def test_eval_detect_scores_a_python_detector_on_the_frames_ours_gets(slipstream_bin):
    runs = [slipstream(slipstream_bin, "eval", "detect", "--scenario", "cut-in", "--duration", "10", "--json", *more)
            for more in ((), ("--detector", DETECTOR))]
    ours, mine = (json.loads(r.stdout) for r in runs)
    assert mine["own"]["command"] == [sys.executable, OWN_DETECT] and ours["own"] is None, mine["own"]
    assert mine["unanswered_frames"] == 0
    # The same frames and ground truth: every frame scored, the same vehicles to find.
    o, m = ours["overall"], mine["overall"]
    assert m["frames"] == o["frames"] > 150 and m["eligible"] == o["eligible"] > 0, (o, m)
    # The teaching detector finds the near vehicles and places them within a few per cent.
    assert m["precision"] > 0.9 and m["recall"] > 0.9, m


def test_a_python_detector_closes_the_loop_in_lockstep_the_same_twice(slipstream_bin):
    def run():
        done = slipstream(slipstream_bin, "eval", "acc", "--scenario", "cut-in", "--json", "--detector", DETECTOR)
        assert done.stdout, done.stderr[-3000:]
        return json.loads(done.stdout)
    first, second = run(), run()
    r = first["results"][0]
    assert r["perception"] == "camera" and r["lockstep_timeouts"] == 0 and r["metrics"]["collisions"] == 0, r
    assert first["results"][0]["metrics"] == second["results"][0]["metrics"]
    assert first["own"]["detector"]["command"] == [sys.executable, OWN_DETECT]


def test_a_detector_that_dies_is_named_with_its_last_words(slipstream_bin):
    done = slipstream(slipstream_bin, "eval", "detect", "--scenario", "cut-in", "--duration", "10",
                      "--detector", f"{sys.executable} tests/python/bad_detectors.py crash", timeout=120)
    assert done.returncode == 1, done.stderr[-2000:]
    assert "detector exited at frame" in done.stderr, done.stderr[-2000:]
    assert "RuntimeError: the network's weights did not load" in done.stderr, done.stderr[-2000:]


def test_eval_detect_takes_the_detector_of_a_loop_file_and_nothing_else(slipstream_bin, tmp_path):
    detector = f'detector: {{ command: ["{sys.executable}", "{ROOT / OWN_DETECT}"], env: {{ OMP_NUM_THREADS: "1" }} }}'
    (tmp_path / "mine.json5").write_text(f"{{ {detector} }}")
    done = slipstream(slipstream_bin, "eval", "detect", "--scenario", "cut-in", "--duration", "4", "--json",
                      "--loop", str(tmp_path / "mine.json5"))
    assert done.returncode == 0, done.stderr[-2000:]
    mine = json.loads(done.stdout)
    assert mine["own"]["command"][1] == str(ROOT / OWN_DETECT) and mine["own"]["run"]["env"] == {"OMP_NUM_THREADS": "1"}
    assert mine["overall"]["frames"] > 50 and mine["unanswered_frames"] == 0, mine["overall"]
    # A controller in the file is no part of eval detect: refused naming the file, key and fix.
    (tmp_path / "loop.json5").write_text(f'{{ {detector}, controller: {{ builtin: true }} }}')
    refused = slipstream(slipstream_bin, "eval", "detect", "--scenario", "cut-in", "--loop", str(tmp_path / "loop.json5"))
    assert refused.returncode != 0 and f"{tmp_path / 'loop.json5'}: key `controller`" in refused.stderr, refused.stderr
    assert "fix: " in refused.stderr
    # Readiness by a first sample cannot come before the first frame, which waits for the token.
    (tmp_path / "sample.json5").write_text("{ " + detector.replace("env:", 'ready: { sample: "perception/objects" }, env:') + " }")
    refused = slipstream(slipstream_bin, "eval", "detect", "--scenario", "cut-in", "--loop", str(tmp_path / "sample.json5"))
    assert refused.returncode != 0 and "key `detector.ready.sample`" in refused.stderr, refused.stderr
