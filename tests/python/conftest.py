"""Shared fixtures: the Rust binary under test. The Python client is imported as installed
(scripts/test.sh: pip install -e clients/python)."""

import os
import pathlib
import signal
import socket
import tempfile

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]

# A test command started in the background (`bash scripts/test.sh &`, nohup) has SIGINT
# ignored, and an ignored signal stays ignored in every process started from here: the Python
# nodes and tools the tests stop with SIGINT, as Ctrl-C would, would never stop. With a handler
# in this process each child starts with the default action instead.
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)


def hermetic_zenoh_config():
    """config/zenoh.json5 without its rendezvous (tcp/127.0.0.1:7447): it dials nothing and
    listens on a port the kernel picks. Every process a test starts gets it through
    SLIPSTREAM_ZENOH_CONFIG unless the test names another (`-c`, its own environment), so the
    tests' nodes meet only whom a test connects them to, never a loop a developer left running
    on the machine (the test command keeps one running beside them). The commands typed as a
    user types them run on hosts of their own with the default config (user_host.py)."""
    default = (ROOT / "config" / "zenoh.json5").read_text()
    dial, listen = 'endpoints: ["tcp/127.0.0.1:7447"],', 'endpoints: ["tcp/127.0.0.1:7447", "tcp/127.0.0.1:0"],'
    assert dial in default and listen in default, "config/zenoh.json5's rendezvous moved: update conftest.py"
    own = default.replace(listen, 'endpoints: ["tcp/127.0.0.1:0"],').replace(dial, "endpoints: [],")
    path = pathlib.Path(tempfile.gettempdir()) / f"slipstream-pytest-{os.getpid()}-zenoh.json5"
    path.write_text(own)
    return path


os.environ["SLIPSTREAM_ZENOH_CONFIG"] = str(hermetic_zenoh_config())


@pytest.fixture(scope="session")
def slipstream_bin():
    path = pathlib.Path(os.environ.get("SLIPSTREAM_BIN", ROOT / "target" / "release" / "slipstream"))
    if not path.is_file():
        pytest.fail(f"{path} is missing: build it with `cargo build --release` (scripts/test.sh does)")
    return str(path)


# The ports tests give the listeners they start come from below the kernel's ephemeral range
# (ip_local_port_range, 32768 and up by default), where no port-0 listener and no outgoing
# connection of another process can take one between the test choosing it and its process
# binding it, and from a block of its own for each pytest-xdist worker, so two tests running at
# once never share a port. Sharing one, a test's node would dial the other test's loop, and two
# loops in the default namespace would drive each other's cars.
PORT_BLOCK = 2000
FIRST_PORT = 20000
_ports_given = {}


def reserve_port():
    """A loopback TCP port free now, never given to another test of this run."""
    worker = os.environ.get("PYTEST_XDIST_WORKER", "gw0")
    index = int(worker[2:]) % 6 if worker[2:].isdigit() else 0
    low = FIRST_PORT + index * PORT_BLOCK
    for _ in range(PORT_BLOCK):
        offset = _ports_given.get(low, 0)
        _ports_given[low] = (offset + 1) % PORT_BLOCK
        port = low + offset
        with socket.socket() as s:
            try:
                s.bind(("127.0.0.1", port))
            except OSError:
                continue  # in use, or still closing after an earlier run
        return port
    pytest.fail(f"no free port in {low}-{low + PORT_BLOCK - 1}")


@pytest.fixture
def free_port():
    return reserve_port()


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
