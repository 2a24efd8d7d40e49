"""Three controlled vehicles in one world across PCs (tests/python/netns.py `Subnets`): the
simulator on one subnet behind the first router, each car's ACC on a host of its own on a third
subnet behind the second router, the two routers meshed over a second subnet. The first router
is ours (`slipstream router`), the second Eclipse's build of Zenoh's router (eclipse_router.py:
the eclipse-zenoh wheel's runtime with zenohd's flags; zenohd is not installable here). Every
node a client of its router (config/client.json5), shared memory off, so every message of the loop
crosses two routers and the bridges. In lockstep the simulator waits at each step for all three
cars' commands: the run ends with no lockstep timeout and each car followed its own commands.
Ground-truth perception: three cameras' raw frames across two routers would measure the
machine's two cores, not the loop (docs/simulator.md). Figures to target/test-reports/netns.json."""

import json
import subprocess
import sys

import pytest
from conftest import ROOT
from netns import Subnets, can_create_namespaces
from test_netns import NO_SHM, bins, record, running_on

why = can_create_namespaces()
pytestmark = pytest.mark.skipif(why is not None, reason=f"namespace test: {why}")

CARS = ["car1", "car2", "car3"]
LAYOUT = {"a": ["r1", "simpc"], "b": ["r1", "r2"], "c": ["r2", *CARS]}
# Three cars 55 m apart behind a leader that dips from 25 to 20 m/s and back.
SCENARIO = """{
  name: "three-across-routers", duration_s: 20, seed: 3,
  egos: [
    { namespace: "car1", lane: 1, s_m: 500, speed_mps: 25, time_gap_s: 1.8 },
    { namespace: "car2", lane: 1, s_m: 445, speed_mps: 25, time_gap_s: 1.8 },
    { namespace: "car3", lane: 1, s_m: 390, speed_mps: 25, time_gap_s: 1.8 },
  ],
  traffic: [ { lane: 1, gap_m: 50, speed_mps: 25, follow: false, actions: [
    { at_s: 4, speed_mps: 20, accel_mps2: 2 }, { at_s: 10, speed_mps: 25, accel_mps2: 1 } ] } ],
}"""


def test_three_cars_each_on_its_own_host_close_one_lockstep_loop_across_two_routers(tmp_path, slipstream_bin):
    b = bins(slipstream_bin)
    scenario = tmp_path / "three.json5"
    scenario.write_text(SCENARIO)
    nets = Subnets(LAYOUT)
    router = [b["slipstream"], "router", "-c", "config/router.json5", *NO_SHM]

    def client(role, subnet, router_role):
        ep = f"tcp/{nets.addr[(router_role, subnet)]}:7447"
        return ["-c", "config/client.json5", "-e", ep, *NO_SHM]

    with running_on(nets, tmp_path / "logs") as hosts:
        hosts.start("r1", router, name="r1")
        eclipse = [sys.executable, str(ROOT / "tests/python/eclipse_router.py"), "-c", "config/router.json5", *NO_SHM]
        hosts.start("r2", [*eclipse, "-e", f"tcp/{nets.addr[('r1', 'b')]}:7447"], name="r2")
        for car in CARS:
            hosts.start(car, [b["slipstream-acc"], "-n", f"lab/{car}", "--perception", "ground-truth", "--lockstep",
                              "--time-gap", "1.8", *client(car, "c", "r2")], name=f"{car}-acc")
        sim = subprocess.run(["ip", "netns", "exec", nets.ns["simpc"], b["slipstream-sim"], "-n", "lab",
                              *client("simpc", "a", "r1"), "--scenario", str(scenario), "--mode", "lockstep",
                              "--wait-for", "acc", "--json"], capture_output=True, text=True, timeout=240)
        logs = hosts.tails()
    assert sim.returncode == 0, f"{sim.stderr[-3000:]}\n{logs}"
    report = json.loads(sim.stdout)
    assert report["end"]["success"] and report["lockstep_timeouts"] == 0, (report["end"], logs)
    egos = report["egos"]
    assert [e["namespace"] for e in egos] == CARS, egos
    for e in egos:
        # Every car's controller answered each step; none of its commands came too late or from
        # another car's controller.
        assert e["collisions"] == 0 and e["lockstep_timeouts"] == 0 and e["control_foreign"] == 0, e
    assert report["collisions_between_egos"] == 0
    record("three_cars_across_two_routers", {"sim_time_s": report["sim_time_s"], "wall_time_s": report["wall_time_s"],
                                             "real_time_factor": report["real_time_factor"]})
