"""Controllers that break the node contract on purpose, for tests/python/test_own_nodes.py:

    python3 bad_controllers.py silent     # declares its token, never answers
    python3 bad_controllers.py crash      # answers for a simulated second, then raises
    python3 bad_controllers.py crash-once MARK  # as crash, the first time only (MARK: a file
                                                # it leaves); then the example's time gap law
    python3 bad_controllers.py wrong-step # the example, each answer naming the next step
    python3 bad_controllers.py wall-stamp # the example, each answer stamped with the wall clock
    python3 bad_controllers.py no-token   # the example, its liveliness token withdrawn
    python3 bad_controllers.py garbage    # the example, each answer's payload replaced by bytes
                                          # that decode as nothing
"""

import os
import sys
import time

import zenoh

from slipstream_client import Topics
from slipstream_client.controller import ControllerNode, run_controller


def silent():
    topics = Topics.load()
    with zenoh.open(zenoh.Config.from_file(os.environ["SLIPSTREAM_ZENOH_CONFIG"])) as session:
        token = session.liveliness().declare_token(topics.node_key(os.environ["SLIPSTREAM_NODE"]))
        try:
            while True:
                time.sleep(0.1)
        except KeyboardInterrupt:
            token.undeclare()


def crash(ego, ahead, settings):
    if ego.t_s > 1.0:
        raise RuntimeError("the model diverged")
    return 0.0


def example():
    sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "..", "clients", "python", "examples"))
    import own_acc

    return own_acc.control


def broken(mode):
    """The example controller with one rule of the contract broken."""
    put, start = ControllerNode._put, ControllerNode.start

    def bad_put(self, key, kind, t_ns, body):
        if key == "vehicle/control" and mode == "garbage":
            self.pubs[key].put(b"\xde\xad\xbe\xef not a message", attachment=self.name.encode())
            return
        if key == "vehicle/control" and mode == "wrong-step":
            body = dict(body, answers_step=body["answers_step"] + 1)
        if key == "vehicle/control" and mode == "wall-stamp":
            t_ns = time.time_ns()
        put(self, key, kind, t_ns, body)

    def bad_start(self):
        start(self)
        if mode == "no-token":
            self.token.undeclare()
            self.token = None

    ControllerNode._put, ControllerNode.start = bad_put, bad_start
    run_controller(example())


def crash_once(mark):
    control = example()
    if os.path.exists(mark):
        run_controller(control)
    else:
        with open(mark, "w") as f:
            f.write("crashed once\n")
        run_controller(crash)


if __name__ == "__main__":
    mode = sys.argv.pop(1)
    if mode == "silent":
        silent()
    elif mode == "crash-once":
        crash_once(sys.argv.pop(1))
    elif mode in ("wrong-step", "wall-stamp", "no-token", "garbage"):
        broken(mode)
    else:
        run_controller(crash)
