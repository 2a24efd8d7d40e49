"""A Zenoh router built by Eclipse, not by us: the eclipse-zenoh wheel's own Zenoh runtime opened
in router mode, with zenohd's command-line flags (-c FILE, -l, -e, --no-multicast-scouting,
--cfg KEY:VALUE). zenohd is that runtime plus a plugin loader; no zenohd binary is installable on
this machine, so the tests that name "the official router" run this one and say so.

    python eclipse_router.py -c config/router.json5 -l tcp/127.0.0.1:7447 [-e tcp/OTHER:7447]

Prints `router <zid> listening on <locators>` once it listens, then runs until SIGINT/SIGTERM."""

import argparse
import json
import signal
import threading

import zenoh


def config(args):
    conf = zenoh.Config.from_file(args.config) if args.config else zenoh.Config()
    conf.insert_json5("mode", '"router"')
    if args.listen:
        conf.insert_json5("listen/endpoints", json.dumps(args.listen))
    if args.connect:
        conf.insert_json5("connect/endpoints", json.dumps(args.connect))
    if args.no_multicast_scouting:
        conf.insert_json5("scouting/multicast/enabled", "false")
    for kv in args.cfg:
        key, _, value = kv.partition(":")
        conf.insert_json5(key, value)
    return conf


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("-c", "--config")
    p.add_argument("-l", "--listen", action="append", default=[])
    p.add_argument("-e", "--connect", action="append", default=[])
    p.add_argument("--no-multicast-scouting", action="store_true")
    p.add_argument("--cfg", action="append", default=[])
    args = p.parse_args()
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    session = zenoh.open(config(args))
    # Zenoh's Python API lists no locators of its own session; the endpoints asked are printed.
    print(f"router {session.zid()} listening on {', '.join(args.listen) or 'the config file'}", flush=True)
    stop.wait()
    session.close()


if __name__ == "__main__":
    main()
