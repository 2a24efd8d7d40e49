"""`slipstream up` as a supervisor (systemd, docker, a shell closing) treats it: SIGTERM and SIGHUP
stop it as Ctrl-C does (nodes stopped, report written, exit 130), and when it is killed outright
(SIGKILL) its nodes end with it. Nodes are found from /proc by their parent, so a leftover node
shows whatever its name."""

import json
import os
import pathlib
import signal
import subprocess
import time

import pytest
from conftest import ROOT


def children_of(pid):
    kids = []
    for stat in pathlib.Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == pid:
            kids.append(int(stat.parent.name))
    return kids


def alive(pid):
    try:
        state = pathlib.Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


def start_up(slipstream_bin, free_port, report):
    up = subprocess.Popen(
        [slipstream_bin, "-l", f"tcp/127.0.0.1:{free_port}", "up", "--scenario", "cut-in", "--duration", "60",
         "--plain", "--report", str(report)],
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, cwd=ROOT)
    deadline = time.time() + 60
    while time.time() < deadline and len(children_of(up.pid)) < 3:
        assert up.poll() is None, up.stderr.read()
        time.sleep(0.2)
    nodes = children_of(up.pid)
    assert len(nodes) == 3, nodes
    time.sleep(2.0)
    return up, nodes


def wait_gone(pids, seconds):
    deadline = time.time() + seconds
    while time.time() < deadline and any(alive(p) for p in pids):
        time.sleep(0.1)
    return [p for p in pids if alive(p)]


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP])
def test_a_stop_signal_stops_the_nodes_and_writes_the_report(slipstream_bin, free_port, tmp_path, sig):
    up, nodes = start_up(slipstream_bin, free_port, tmp_path / "report")
    up.send_signal(sig)
    _, err = up.communicate(timeout=60)
    assert up.returncode == 130, err[-2000:]
    assert wait_gone(nodes, 10) == [], "nodes outlived up"
    report = json.loads((tmp_path / "report" / "report.json").read_text())
    assert report["interrupted"] is True
    assert signal.Signals(sig).name in report["ended"] or signal.Signals(sig).name in err, (report["ended"], err)


def test_nodes_end_with_up_when_it_is_killed(slipstream_bin, free_port, tmp_path):
    up, nodes = start_up(slipstream_bin, free_port, tmp_path / "report")
    os.kill(up.pid, signal.SIGKILL)
    up.wait(timeout=10)
    left = wait_gone(nodes, 15)
    for p in left:
        os.kill(p, signal.SIGKILL)
    assert left == [], "nodes outlived a killed up"
