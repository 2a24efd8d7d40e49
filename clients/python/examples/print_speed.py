#!/usr/bin/env python3
"""Prints the ego vehicle's speed as the simulator publishes it (vehicle/speed, 100 Hz).

    python3 clients/python/examples/print_speed.py            # next to `slipstream up`
    python3 clients/python/examples/print_speed.py -m client -e tcp/192.168.1.10:7447 --every 10

Each line: simulation time, speed, sequence number and the age of the message when it was
read (publisher wall clock to ours: meaningful across PCs only with synchronised clocks)."""

import argparse
import threading
import time

import _path  # noqa: F401  (source checkout)

from slipstream_client import BadPayloads, WireError, cli, connect, decode


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--count", type=int, default=0, help="stop after N messages [default: run until Ctrl-C]")
    parser.add_argument("--every", type=int, default=1, help="print one message in N [default: 1]")
    connect.add_args(parser)
    args = parser.parse_args()
    session, topics = cli.open_session(args)
    key = topics.key("vehicle/speed")
    done = threading.Event()
    seen = {"n": 0}
    bad = BadPayloads()

    def on_sample(sample):
        try:
            _, header, speed = decode(sample.payload.to_bytes(), expected="Speed")
        except WireError as e:
            return bad(key, e)
        if done.is_set():
            return
        seen["n"] += 1
        if (seen["n"] - 1) % args.every == 0:
            age_ms = (time.time_ns() - header["stamp_pub_ns"]) / 1e6
            v = speed["speed_mps"]
            print(f"t={header['stamp_sim_ns'] / 1e9:9.3f} s  speed {v:6.2f} m/s ({v * 3.6:6.1f} km/h)  "
                  f"seq {header['seq']:7d}  age {age_ms:6.2f} ms", flush=True)
        if args.count and seen["n"] >= args.count:
            done.set()

    print(f"# listening on {key}", flush=True)
    sub = session.declare_subscriber(key, on_sample)
    try:
        while not done.wait(0.2):
            pass
    except KeyboardInterrupt:
        pass
    finally:
        sub.undeclare()
        session.close()


if __name__ == "__main__":
    main()
