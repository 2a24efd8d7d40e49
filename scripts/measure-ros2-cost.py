#!/usr/bin/env python3
"""Figures for docs/ros2.md ("What it costs"): the loop's real-time factor in fast mode without
and with its ROS 2 face (`up --ros2`, every route on) while a subscriber takes every ROS 2 key,
in the same run, alternating, REPEAT times each; the median of each and their ratio. Also the
bridge's counts (sent, dropped for a slow subscriber). Needs a release build and the venv of
scripts/test.sh. Usage: .venv/bin/python scripts/measure-ros2-cost.py [REPEAT] [SIM_SECONDS]"""

import json
import os
import pathlib
import socket
import statistics
import subprocess
import sys
import tempfile
import threading

import zenoh

ROOT = pathlib.Path(__file__).resolve().parents[1]
BIN = ROOT / "target" / "release" / "slipstream"


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def run(ros2, seconds, tmp):
    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    report = pathlib.Path(tmp) / f"run-{ros2}-{port}"
    argv = [str(BIN), "-l", endpoint, "up", "--mode", "fast", "--scenario", "cut-in", "--duration", str(seconds),
            "--plain", "--report", str(report)] + (["--ros2"] if ros2 else [])
    up = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, cwd=ROOT)
    taken = {"messages": 0, "bytes": 0}
    lock = threading.Lock()

    def on_sample(sample):
        with lock:
            taken["messages"] += 1
            taken["bytes"] += len(sample.payload)

    conf = zenoh.Config()
    conf.insert_json5("mode", '"peer"')
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("listen/endpoints", "[]")
    conf.insert_json5("connect/endpoints", json.dumps([endpoint]))
    with zenoh.open(conf) as session:
        sub = session.declare_subscriber("0/**", on_sample) if ros2 and not os.environ.get("NO_SUBSCRIBER") else None
        up.wait(timeout=600)
        if sub:
            sub.undeclare()
    data = json.loads((report / "report.json").read_text())
    return data["real_time_factor"], data.get("ros2"), taken


def main():
    repeat = int(sys.argv[1]) if len(sys.argv) > 1 else 3
    seconds = float(sys.argv[2]) if len(sys.argv) > 2 else 30
    without, with_ros = [], []
    last = None
    with tempfile.TemporaryDirectory() as tmp:
        for i in range(repeat):
            for ros2 in ((False, True) if i % 2 == 0 else (True, False)):
                rtf, stats, taken = run(ros2, seconds, tmp)
                (with_ros if ros2 else without).append(rtf)
                if ros2:
                    last = (stats, taken)
                print(f"run {i + 1} {'with' if ros2 else 'without'} ROS 2: RTF {rtf:.2f}", file=sys.stderr)
    a, b = statistics.median(without), statistics.median(with_ros)
    stats, taken = last
    print(json.dumps({
        "command": f"scripts/measure-ros2-cost.py {repeat} {seconds:g}",
        "rtf_without_median": round(a, 3), "rtf_with_median": round(b, 3), "ratio": round(b / a, 3),
        "rtf_without": [round(x, 3) for x in without], "rtf_with": [round(x, 3) for x in with_ros],
        "last_run_routes": stats["routes"] if stats else None,
        "last_run_subscriber": taken,
    }, indent=1))


if __name__ == "__main__":
    main()
