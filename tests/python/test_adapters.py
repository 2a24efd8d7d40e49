"""The CARLA and CoppeliaSim adapters keep the simulator contract, run against stand-ins of
their servers (there is no CARLA or CoppeliaSim here): CARLA's on the `carla` package's own
value types, CoppeliaSim's speaking the ZMQ remote API to CoppeliaSim's own client package.
An adapter that loses its server says so and exits non-zero; `up --sim external` closes the
loop around the CARLA adapter."""

import json
import os
import socket
import subprocess
import sys
import time

import pytest
from conftest import ROOT, reserve_port
from test_conform import Running, assert_keeps_the_contract, conform

HERE = ROOT / "tests" / "python"
COPPELIA = ROOT / "clients" / "python" / "adapters" / "coppeliasim_adapter.py"


def carla(endpoint, ns, *args, env=None):
    return Running([sys.executable, str(HERE / "carla_standin.py"), *args, "-l", endpoint, "-e", endpoint,
                    "-n", ns], env=env)


def coppelia_server(port, env=None):
    """The stand-in server, returned once its port accepts connections: the adapter gives up
    on a server it cannot reach within its --timeout, and a loaded machine starts Python slowly."""
    server = Running([sys.executable, str(HERE / "coppeliasim_standin.py"), str(port)], env=env)
    deadline = time.monotonic() + 20
    while time.monotonic() < deadline and server.proc.poll() is None:
        try:
            socket.create_connection(("127.0.0.1", port), timeout=1).close()
            break
        except OSError:
            time.sleep(0.1)
    return server


def other_free_port(taken):
    """A free loopback port other than `taken` (the next port up may be in use)."""
    while True:
        port = reserve_port()
        if port != taken:
            return port


def coppelia(server_port, endpoint, ns, *args):
    return Running([sys.executable, str(COPPELIA), "--port", str(server_port), "--timeout", "3", "--ego", "/Car",
                    "--camera", "/Car/visionSensor", "--traffic", "/Lead", "--traffic", "/Other", *args,
                    "-l", endpoint, "-e", endpoint, "-n", ns])


def lockstep_flag(mode):
    return ["--lockstep"] if mode == "lockstep" else []


@pytest.mark.parametrize("mode", ["realtime", "fast", "lockstep"])
def test_the_carla_adapter_keeps_the_contract_on_the_stand_in(slipstream_bin, free_port, mode):
    endpoint, ns = f"tcp/127.0.0.1:{free_port}", f"carla-{mode}"
    with carla(endpoint, ns, "--mode", mode):
        code, verdicts = conform(slipstream_bin, endpoint, ns, *lockstep_flag(mode))
    assert_keeps_the_contract(code, verdicts)
    assert verdicts["optional.objects"]["outcome"] == "PASS"


@pytest.mark.parametrize("mode", ["realtime", "lockstep"])
def test_the_coppeliasim_adapter_keeps_the_contract_on_the_stand_in(slipstream_bin, free_port, mode):
    endpoint, ns = f"tcp/127.0.0.1:{free_port}", f"coppelia-{mode}"
    server_port = other_free_port(free_port)
    with coppelia_server(server_port), coppelia(server_port, endpoint, ns, "--mode", mode):
        code, verdicts = conform(slipstream_bin, endpoint, ns, *lockstep_flag(mode))
    assert_keeps_the_contract(code, verdicts)
    assert verdicts["optional.objects"]["outcome"] == "PASS"


def test_an_adapter_that_loses_its_server_says_so_and_exits_non_zero(free_port):
    env = {**os.environ, "STANDIN_DIE_AFTER": "1.0"}
    endpoint = f"tcp/127.0.0.1:{free_port}"
    with carla(endpoint, "carla-dies", "--mode", "fast", env=env) as run:
        _, err = run.proc.communicate(timeout=60)
    assert run.proc.returncode == 1 and "lost the CARLA server" in err, err

    server_port = other_free_port(free_port)
    with coppelia_server(server_port, env=env), coppelia(server_port, endpoint, "coppelia-dies", "--mode", "fast") as run:
        _, err = run.proc.communicate(timeout=60)
    assert run.proc.returncode == 1 and "lost CoppeliaSim" in err, err

    started = time.monotonic()
    out = subprocess.run([sys.executable, str(COPPELIA), "--port", str(server_port), "--timeout", "1"],
                         capture_output=True, text=True, timeout=60)
    assert out.returncode == 1 and "no answer from CoppeliaSim" in out.stderr, out.stderr
    assert time.monotonic() - started < 30


def test_up_closes_the_loop_around_the_carla_adapter(slipstream_bin, free_port, tmp_path):
    endpoint, ns = f"tcp/127.0.0.1:{free_port}", "carla-up"
    report_dir = tmp_path / "report"
    adapter = Running([sys.executable, str(HERE / "carla_standin.py"), "--mode", "lockstep", "--duration", "15",
                       "-e", endpoint, "-n", ns])
    with adapter:
        up = subprocess.run(
            [slipstream_bin, "-l", endpoint, "-n", ns, "up", "--sim", "external", "--mode", "lockstep", "--plain",
             "--report", str(report_dir)],
            capture_output=True, text=True, timeout=300,
        )
        out, _ = adapter.proc.communicate(timeout=30)
    assert up.returncode == 0, up.stderr[-3000:]
    report = json.loads((report_dir / "report.json").read_text())
    assert report["ended"] == "duration reached" and report["collisions"] == 0, report["ended"]
    assert report["ground_truth"] and report["metrics"]["min_gap_m"] > 10, report["metrics"]
    rows = {r["key"]: r for r in report["topics"]}
    assert rows[f"{ns}/perception/objects"]["from"] == "detect"
    assert "# 1500 steps" in out, out
