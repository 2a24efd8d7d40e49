"""Watches the loop from a host of the namespace test and prints JSON lines (run by
test_netns.py through `ip netns exec`):

  {"ev": "ctl", "pub": ns, "perc": ns|null}      a vehicle/control and its perception stamp
  {"ev": "applied", "cmd": ns, "at": ns}         the simulator applied a new command (vehicle/state)
  {"ev": "tick", "t": ns, "state": n, "det": n, "frame": n,   counts over the last 250 ms,
   "speed_ms": [..], "frame_ms": [..]}                        and the one-way latencies (publish
                                                              to this callback) of speed and frames

All stamps are wall-clock nanoseconds of one machine (namespaces share the clock)."""

import json
import threading
import time


from slipstream_client import WireError, cli, connect, decode


def main():
    import argparse

    parser = argparse.ArgumentParser()
    connect.add_args(parser)
    parser.add_argument("--seconds", type=float, default=300)
    args = parser.parse_args()
    session, topics = cli.open_session(args)
    lock = threading.Lock()
    counts = {"state": 0, "det": 0, "frame": 0}
    latencies = {"speed_ms": [], "frame_ms": []}
    last = {"cmd": None}

    def out(obj):
        with lock:
            print(json.dumps(obj), flush=True)

    def on_control(sample):
        try:
            _, h, c = decode(sample.payload.to_bytes(), expected="ControlCommand")
        except WireError:
            return
        out({"ev": "ctl", "pub": h["stamp_pub_ns"], "perc": c["perception_stamp_pub_ns"]})

    def on_state(sample):
        try:
            _, _, s = decode(sample.payload.to_bytes(), expected="VehicleState")
        except WireError:
            return
        timing = s["control_timing"]
        with lock:
            counts["state"] += 1
            new = timing is not None and timing["command_stamp_pub_ns"] != last["cmd"]
            if new:
                last["cmd"] = timing["command_stamp_pub_ns"]
        if new:
            out({"ev": "applied", "cmd": timing["command_stamp_pub_ns"], "at": timing["applied_ns"]})

    def count(name):
        def on_sample(_sample):
            with lock:
                counts[name] += 1
        return on_sample

    def latency(name, kind):
        # Stamped on arrival, before the payload is copied and decoded.
        def on_sample(sample):
            now = time.time_ns()
            payload = sample.payload.to_bytes()
            try:
                _, h, _ = decode(payload, expected=kind, copy=False)
            except WireError:
                return
            with lock:
                latencies[name].append(round((now - h["stamp_pub_ns"]) / 1e6, 3))
                if kind == "CameraFrame":
                    counts["frame"] += 1
        return on_sample

    subs = [
        session.declare_subscriber(topics.key("vehicle/control"), on_control),
        session.declare_subscriber(topics.key("vehicle/state"), on_state),
        session.declare_subscriber(topics.key("perception/objects"), count("det")),
        session.declare_subscriber(topics.read_key("camera/front"), latency("frame_ms", "CameraFrame")),
        session.declare_subscriber(topics.key("vehicle/speed"), latency("speed_ms", "Speed")),
    ]
    end = time.monotonic() + args.seconds
    try:
        while time.monotonic() < end:
            time.sleep(0.25)
            with lock:
                snapshot = {**counts, **latencies}
                for k in counts:
                    counts[k] = 0
                latencies = {k: [] for k in latencies}
            out({"ev": "tick", "t": time.time_ns(), **snapshot})
    except KeyboardInterrupt:
        pass
    finally:
        for s in subs:
            s.undeclare()
        session.close()


if __name__ == "__main__":
    main()
