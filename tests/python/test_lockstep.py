"""A controller written in Python closes the loop with the Rust simulator in lockstep: it
answers every vehicle/state with a ControlCommand naming the step, attached with its node
name, and the simulator waits for it at every step."""

import json
import subprocess
import threading
import time

import zenoh
from conftest import peer_config

from slipstream_client import decode, encode


def test_a_python_controller_drives_the_simulator_in_lockstep(sim_bin, free_port):
    endpoint = f"tcp/127.0.0.1:{free_port}"
    sim = subprocess.Popen(
        [sim_bin, "--scenario", "steady-follow", "--mode", "lockstep", "--wait-for", "pyctl",
         "--duration", "2", "--camera-size", "160x120", "--json", "-l", endpoint, "-e", endpoint,
         # Physics at the state's rate: every step publishes a state and waits for its answer.
         "--physics-hz", "100"],
        stdout=subprocess.PIPE,
    )
    try:
        conf = peer_config(endpoint)
        states = []
        lock = threading.Lock()
        with zenoh.open(conf) as session:
            control = session.declare_publisher("vehicle/control")

            def on_state(sample):
                _, header, state = decode(sample.payload.to_bytes(), expected="VehicleState")
                with lock:
                    seq = len(states)
                    states.append(state)
                command = {"throttle": 0.5, "brake": 0.0, "steer": 0.0, "answers_step": state["step"],
                           "perception_stamp_pub_ns": None}
                stamp = {"seq": seq, "stamp_sim_ns": header["stamp_sim_ns"], "stamp_pub_ns": time.time_ns()}
                control.put(encode("ControlCommand", stamp, command), attachment=b"pyctl")

            sub = session.declare_subscriber("vehicle/state", on_state)
            token = session.liveliness().declare_token("nodes/pyctl")
            out, _ = sim.communicate(timeout=90)
            token.undeclare()
            sub.undeclare()
        report = json.loads(out)
        assert sim.returncode == 0
        assert (report["steps"], report["lockstep_timeouts"]) == (200, 0), report
        assert report["end"]["success"], report
        with lock:
            last = states[-1]
        assert last["step"] == 199 and last["applied"]["answers_step"] == 198, last
        assert last["applied"]["throttle"] == 0.5, last
    finally:
        if sim.poll() is None:
            sim.kill()
            sim.wait(timeout=10)
