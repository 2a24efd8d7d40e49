"""Helpers for command-line programs on the client (the examples, the reference simulator, the
simulator adapters). Unlike the rest of the package, they may print, install a signal handler
and end the process: a library caller uses `connect.open_from_args` and handles its errors."""

import argparse
import signal
import sys
import threading
from typing import Callable, Dict, Optional, Tuple, Type

import zenoh

from . import connect
from .keys import ConfigError, Topics


def add_clock_args(parser: argparse.ArgumentParser, mode: str, duration_s: float) -> None:
    """The flags every simulator on the client takes for its clock and lockstep: --mode,
    --duration, --camera-hz, --wait-for, --step-timeout (defaults: `mode`, `duration_s`). The
    clock defaults to SLIPSTREAM_CLOCK when set: what a loop hands the simulator it starts."""
    import os

    from .simulator import MODES

    p = parser
    given = os.environ.get("SLIPSTREAM_CLOCK")
    p.add_argument("--mode", choices=MODES, default=given if given in MODES else mode,
                   help=f"[env: SLIPSTREAM_CLOCK; default: {mode}]")
    p.add_argument("--duration", type=float, default=duration_s, help=f"simulated seconds [default: {duration_s:g}]")
    p.add_argument("--camera-hz", type=float, default=20.0, help="frames per simulated second [default: 20]")
    p.add_argument("--wait-for", action="append", metavar="NODE",
                   help="lockstep: the node(s) whose answer each step waits for [default: acc]")
    p.add_argument("--step-timeout", type=float, default=2.0, help="lockstep: seconds a step waits [default: 2]")


def _interrupt(signum, frame):
    raise KeyboardInterrupt


def open_session(args: argparse.Namespace) -> Tuple[zenoh.Session, Topics]:
    """The session and topic keys of `connect.add_args` flags; SIGTERM (a process manager,
    `kill`) then stops the program as Ctrl-C does. A bad flag or config ends the process with
    what to fix. Call it from the main thread."""
    signal.signal(signal.SIGTERM, _interrupt)
    try:
        return connect.open_from_args(args)
    except (connect.ConnectError, ConfigError) as e:
        raise SystemExit(str(e)) from None


def serve(node, session: zenoh.Session, summary: Callable[[], str]) -> None:
    """Runs a loop node (`start()`, `run(stop_event)`, `close()`: a controller or a detector of
    the SDK) until Ctrl-C or SIGTERM, then closes it and the session and prints `summary()`."""
    stop = threading.Event()
    try:
        node.start()
        node.run(stop)
    except KeyboardInterrupt:
        stop.set()
    finally:
        node.close()
        session.close()
        print(summary(), flush=True)


def run_world(side, session: zenoh.Session, make: Callable, failures: Optional[Dict[Type[BaseException], Callable]] = None) -> int:
    """Runs a simulator on `side` to its end, Ctrl-C or SIGTERM, then closes it (when it ended
    cleanly), the side and the session; returns the process's exit code. `make(side)` builds the
    simulator: an object with `run(stop_event) -> steps` and, if it holds something to let go
    of, `close()`. `failures` maps an
    exception type to a function that words it (a lost server): said on stderr, exit code 1;
    the first type that matches, in order."""
    failures = failures or {}
    stop, world, code = threading.Event(), None, 0
    try:
        world = make(side)
        steps = world.run(stop)
        print(f"# {steps} steps, {side.bad.count} undecodable commands", flush=True)
    except KeyboardInterrupt:
        stop.set()
    except tuple(failures) as e:
        words = next(w for kind, w in failures.items() if isinstance(e, kind))
        print(words(e), file=sys.stderr, flush=True)
        code = 1
    finally:
        if world is not None and code == 0 and hasattr(world, "close"):
            world.close()
        side.close()
        session.close()
    return code
