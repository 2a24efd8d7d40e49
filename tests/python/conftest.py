"""Shared fixtures: the Rust binary under test. The Python client is imported as installed
(scripts/test.sh: pip install -e clients/python)."""

import os
import pathlib
import signal
import socket

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]

# A test command started in the background (`bash scripts/test.sh &`, nohup) has SIGINT
# ignored, and an ignored signal stays ignored in every process started from here: the Python
# nodes and tools the tests stop with SIGINT, as Ctrl-C would, would never stop. With a handler
# in this process each child starts with the default action instead.
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)


@pytest.fixture(scope="session")
def slipstream_bin():
    path = pathlib.Path(os.environ.get("SLIPSTREAM_BIN", ROOT / "target" / "release" / "slipstream"))
    if not path.is_file():
        pytest.fail(f"{path} is missing: build it with `cargo build --release` (scripts/test.sh does)")
    return str(path)


@pytest.fixture
def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture(scope="session")
def sim_bin(slipstream_bin):
    path = pathlib.Path(slipstream_bin).parent / "slipstream-sim"
    if not path.is_file():
        pytest.fail(f"{path} is missing: build it with `cargo build --release` (scripts/test.sh does)")
    return str(path)


def peer_config(endpoint):
    """A Python peer that connects to `endpoint` on loopback only: no scouting, no listener."""
    import zenoh

    conf = zenoh.Config()
    conf.insert_json5("mode", '"peer"')
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("listen/endpoints", "[]")
    conf.insert_json5("connect/endpoints", f'["{endpoint}"]')
    return conf
