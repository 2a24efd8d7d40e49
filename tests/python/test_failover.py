"""Two routers meshed across three subnets (tests/python/netns.py `Subnets`): the simulator on
one subnet, the cruise control on a second, the detector and an observer on a third; each
router has a leg in every subnet, and every node is given both routers (client mode,
config/client.json5). The loop starts through the first router; the second comes up and dials
the first; then the first is killed: the clients fail over to the second by themselves, and the
loop closes again. Then the first router comes back, and the second router's host goes dark
(every link down, no TCP reset): the clients fail over when the router's lease (1 s in the
shipped configs) expires. The failover times and their phases go to
target/test-reports/netns.json (docs/deployment.md, "Failover")."""

import subprocess
import time

import pytest
from netns import Subnets, can_create_namespaces
from test_netns import NO_SHM, bins, record, running_on, start_observer

why = can_create_namespaces()
pytestmark = pytest.mark.skipif(why is not None, reason=f"namespace test: {why}")

LAYOUT = {"a": ["r1", "r2", "sim"], "b": ["r1", "r2", "acc"], "c": ["r1", "r2", "detect", "tools"]}


def peers(nets, role):
    """The addresses with an established TCP connection to a router's port 7447 (clients and
    the other router)."""
    out = subprocess.run(["ip", "netns", "exec", nets.ns[role], "ss", "-Htn", "state", "established", "( sport = :7447 )"],
                         capture_output=True, text=True, timeout=10, check=True).stdout
    return [line.split()[-1].rsplit(":", 1)[0] for line in out.splitlines() if line.strip()]


def connections(nets, role):
    return len(peers(nets, role))


def when_clients_on(nets, role, clients, since_ns, timeout_s):
    """For each client name -> address: seconds from `since_ns` until it has a session on the
    router `role` (polled every 20 ms), or None if it has none within the timeout."""
    seen = {}
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline and len(seen) < len(clients):
        on = set(peers(nets, role))
        t = round((time.time_ns() - since_ns) / 1e9, 3)
        seen.update({name: t for name, address in clients.items() if address in on and name not in seen})
        time.sleep(0.02)
    return {name: seen.get(name) for name in clients}


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

    # The clients' addresses: sim on a, acc on b, detect and the observer on c.
    clients = {"sim": nets.addr[("sim", "a")], "acc": nets.addr[("acc", "b")], "detect": nets.addr[("detect", "c")],
               "observer": nets.addr[("tools", "c")]}
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
        # when r2's lease expires, close that session, then dial r1.
        hosts.start("r1", [*router, "-e", f"tcp/{nets.addr[('r2', 'a')]}:7447"], name="r1-again")
        time.sleep(4)
        on_r2_before_dark = connections(nets, "r2")
        t_dark = time.time_ns()
        nets.links("r2", up=False)
        on_r1 = when_clients_on(nets, "r1", clients, t_dark, 60)
        reconnected = max((t for t in on_r1.values() if t is not None), default=None)
        silent_failover = obs.wait_closed_after(t_dark, 60, loop)
        still_running = {n: p.poll() is None for n, p in loop.items()}
    except AssertionError as e:
        raise AssertionError(f"{e}\n{hosts.tails()}") from None
    result = {"first_loop_s": round(first, 3), "tcp_sessions_before_kill": sessions,
              "loop_closed_after_router_killed_s": round(failover, 3),
              "loop_closed_after_router_host_went_dark_s": round(silent_failover, 3),
              "dark_phases_s": {"sessions_on_r2_before": on_r2_before_dark,
                                "each_client_on_the_other_router": on_r1,
                                "then_first_closed_loop": reconnected and round(silent_failover - reconnected, 3)},
              "last_3s_on_the_other_router": after}
    record("router_failover", result)
    print(result)
    assert all(still_running.values()), still_running
    # On the second router the loop runs: states, frames and detections keep coming.
    assert after["state"] > 0 and after["frame"] > 0 and after["det"] > 0, result
    # The loop closed again after each router loss (each wait fails the test when it does not
    # within its cap). How long it took is the report's figure (docs/deployment.md): the
    # shipped configs bound the dark case by lease (1 s) + flush (lease/4) + one dial of the
    # dark router (1 s), ~2.5 s; a pass/fail bound on it would time the machine, not the design.
