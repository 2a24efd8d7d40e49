"""A node that stops reading for a while does not stop the simulator: another node joining
meanwhile and the slow node's own late subscription to a latched topic are answered, and the
simulator keeps its link. Zenoh sends what may not be dropped (a new node's declarations told to
the others, a query's reply) from the receive task that caused it; with the queue towards a
reader that stopped reading full, that send waits for the transmit task to drain the queue. The thread layout of our
processes (crates/contract/src/process.rs) must leave a thread for that: with a single one, the
simulator's Zenoh stood still and closed the link after 5 s ("Unable to push non droppable
network message"), and the node never got the info."""

import subprocess
import threading
import time

import pytest
import zenoh
from conftest import peer_config

# How long the reader stops reading before it subscribes, and after: long enough for the
# simulator's queues towards it to fill at 20 frames/s.
HOLD_S = 1.0
# The late subscriber's wait once the reader reads again: under Zenoh's 5 s before it closes a
# link that cannot take a message.
ANSWER_WITHIN_S = 4.0


class StalledReader:
    """A session whose first sample blocks its receive task until `release()`: a node busy in its
    callback (a slow detector). Frames go through TCP, not shared memory, so the simulator's queue
    towards it fills."""

    def __init__(self, endpoint, namespace):
        conf = peer_config(endpoint)
        conf.insert_json5("transport/shared_memory/enabled", "false")
        self.session = zenoh.open(conf)
        self.held, self.released, self.samples = threading.Event(), threading.Event(), 0
        self.sub = self.session.declare_subscriber(f"{namespace}/**", self._on_sample)

    def _on_sample(self, _sample):
        self.samples += 1
        if not self.released.is_set():
            self.held.set()
            self.released.wait(30)

    def release(self):
        self.released.set()

    def close(self):
        self.release()
        self.sub.undeclare()
        self.session.close()


@pytest.mark.parametrize("mode", ["realtime", "fast"])
def test_a_slow_reader_subscribing_late_gets_the_latched_info_and_keeps_its_link(sim_bin, free_port, mode):
    endpoint, ns = f"tcp/127.0.0.1:{free_port}", f"slow-reader-{mode}"
    sim = subprocess.Popen([sim_bin, "--scenario", "steady-follow", "--mode", mode, "--duration", "600", "-l",
                            endpoint, "-e", endpoint, "-n", ns],
                           stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        time.sleep(0.5)
        reader = StalledReader(endpoint, ns)
        try:
            assert reader.held.wait(20), "the simulator's first message never reached the reader"
            time.sleep(HOLD_S)
            # While the reader is stalled, another node joins the bus (the simulator tells the
            # reader of it) and the reader subscribes to a latched topic (the simulator answers).
            watcher, clock = zenoh.open(peer_config(endpoint)), []
            watch = watcher.declare_subscriber(f"{ns}/sim/clock", lambda s: clock.append(s))
            info = threading.Event()
            late = zenoh.ext.declare_advanced_subscriber(
                reader.session, f"{ns}/camera/front/info", handler=lambda _s: info.set(),
                history=zenoh.ext.HistoryConfig(detect_late_publishers=True, max_samples=1))
            time.sleep(HOLD_S)
            reader.release()
            answered = info.wait(ANSWER_WITHIN_S)
            before = reader.samples
            time.sleep(1.0)
            still_reading = reader.samples - before
            late.undeclare()
            watch.undeclare()
            watcher.close()
        finally:
            reader.close()
        assert clock, "the node that joined got no sim/clock"
    finally:
        sim.terminate()
        err = sim.communicate(timeout=15)[1]
    assert "Closing transport" not in err, f"the simulator closed a link:\n{err[-3000:]}"
    assert answered, f"the late subscriber never got {ns}/camera/front/info within {ANSWER_WITHIN_S} s"
    assert still_reading > 0, "the reader got nothing after it read again"
