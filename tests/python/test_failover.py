"""Two routers meshed across three subnets (tests/python/netns.py `Subnets`): the simulator on
one subnet, the cruise control on a second, the detector and an observer on a third; each
router has a leg in every subnet, and every node is given both routers (client mode,
config/client.json5). The loop starts through the first router; the second comes up and dials
the first; then the first is killed: the clients fail over to the second by themselves, and the
loop closes again. Then the first router comes back, and the second router's host goes dark
(every link down, no TCP reset): the clients fail over when the lease expires. The failover
times go to target/test-reports/netns.json (docs/deployment.md)."""

import subprocess
import time

import pytest
from netns import Subnets, can_create_namespaces
from test_netns import NO_SHM, bins, record, running_on, start_observer

why = can_create_namespaces()
pytestmark = pytest.mark.skipif(why is not None, reason=f"namespace test: {why}")

LAYOUT = {"a": ["r1", "r2", "sim"], "b": ["r1", "r2", "acc"], "c": ["r1", "r2", "detect", "tools"]}


def connections(nets, role):
    """Established TCP connections on a router's port 7447 (clients and the other router)."""
    out = subprocess.run(["ip", "netns", "exec", nets.ns[role], "ss", "-Htn", "state", "established", "( sport = :7447 )"],
                         capture_output=True, text=True, timeout=10, check=True).stdout
    return len([line for line in out.splitlines() if line.strip()])


@pytest.fixture
def subnets(tmp_path):
    nets = Subnets(LAYOUT)
    with running_on(nets, tmp_path / "logs") as hosts:
        yield nets, hosts


def test_killing_one_of_two_meshed_routers_keeps_the_loop_running(subnets, slipstream_bin):
    nets, hosts = subnets
    b = bins(slipstream_bin)
    router = [b["slipstream"], "router", "-c", "config/router.json5", *NO_SHM]
    hosts.start("r1", router, name="r1")

    def client(subnet):
        # Both routers, the first one first.
        eps = [x for r in ("r1", "r2") for x in ("-e", f"tcp/{nets.addr[(r, subnet)]}:7447")]
        return ["-c", "config/client.json5", *eps, *NO_SHM]

    t0 = time.time_ns()
    hosts.start("acc", [b["slipstream-acc"], "--perception", "camera", *client("b")])
    hosts.start("detect", [b["slipstream-detect"], *client("c")])
    hosts.start("sim", [b["slipstream-sim"], "--scenario", "steady-follow", "--duration", "600", *client("a")])
    obs = start_observer(hosts, [*client("c"), "--cfg", "connect/retry:{period_init_ms:100,period_max_ms:200}"])
    loop = hosts.nodes("sim", "detect", "acc")
    try:
        first = obs.wait_closed_after(t0, 60, loop)
        # The second router comes up once the loop runs through the first (so every node is
        # on r1), and meshes with it.
        hosts.start("r2", [*router, "-e", f"tcp/{nets.addr[('r1', 'a')]}:7447"], name="r2")
        time.sleep(4)
        sessions = {r: connections(nets, r) for r in ("r1", "r2")}
        t_kill = time.time_ns()
        hosts.procs["r1"].kill()
        hosts.procs["r1"].wait(timeout=10)
        failover = obs.wait_closed_after(t_kill, 60, loop)
        time.sleep(3)
        t1 = time.time_ns()
        after = obs.counts(t1 - 3_000_000_000, t1)
        # Now the other way, the hard way: r1 comes back and meshes with r2, then r2's host
        # goes silent (every leg down: no TCP reset reaches anyone). The clients notice only
        # when Zenoh's lease (10 s) expires, then dial r1.
        hosts.start("r1", [*router, "-e", f"tcp/{nets.addr[('r2', 'a')]}:7447"], name="r1-again")
        time.sleep(4)
        t_dark = time.time_ns()
        nets.links("r2", up=False)
        silent_failover = obs.wait_closed_after(t_dark, 60, loop)
        still_running = {n: p.poll() is None for n, p in loop.items()}
    except AssertionError as e:
        raise AssertionError(f"{e}\n{hosts.tails()}") from None
    result = {"first_loop_s": round(first, 3), "tcp_sessions_before_kill": sessions,
              "loop_closed_after_router_killed_s": round(failover, 3),
              "loop_closed_after_router_host_went_dark_s": round(silent_failover, 3),
              "last_3s_on_the_other_router": after}
    record("router_failover", result)
    print(result)
    assert all(still_running.values()), still_running
    # On the second router the loop runs: states, frames and detections keep coming.
    assert after["state"] > 0 and after["frame"] > 0 and after["det"] > 0, result
    assert failover < 30 and silent_failover < 60, result
