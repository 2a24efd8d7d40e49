"""Controllers that break the node contract on purpose, for tests/python/test_own_nodes.py:

    python3 bad_controllers.py silent     # declares its token, never answers
    python3 bad_controllers.py crash      # answers for a simulated second, then raises
    python3 bad_controllers.py crash-once MARK  # as crash, the first time only (MARK: a file
                                                # it leaves); then the example's time gap law
"""

import os
import sys
import time

import zenoh

from slipstream_client import Topics
from slipstream_client.controller import run_controller


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


def crash_once(mark):
    sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "..", "clients", "python", "examples"))
    import own_acc

    if os.path.exists(mark):
        run_controller(own_acc.control)
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
    else:
        run_controller(crash)
