#!/usr/bin/env python3
"""A cruise controller in Python that closes the loop with the Rust simulator: it reads
vehicle/speed and the ground-truth objects, and publishes vehicle/control.

    slipstream-sim --scenario steady-follow &                   # or on another PC
    python3 clients/python/examples/cruise_controller.py --set-speed 30

Holds --set-speed, or --time-gap seconds behind the nearest vehicle in the ego's lane,
whichever asks for less acceleration. A teaching example of the interfaces, not the Rust
slipstream-acc (no estimator, no emergency logic). It declares the liveliness token
nodes/<--name> and attaches its name to each command, as the Rust nodes do, so
`slipstream top` lists it and a lockstep simulator could wait for it."""

import argparse
import math
import threading
import time

import _path  # noqa: F401  (source checkout)

from slipstream_client import BadPayloads, WireError, cli, connect, decode, encode

# The simulator's default car (config/acc.json5 "vehicle"): feed-forward from acceleration to pedals.
MASS_KG, MAX_FORCE_N, MAX_POWER_W, MAX_BRAKE_MPS2 = 1500.0, 6500.0, 110000.0, 9.0
DRAG_AREA_M2, ROLLING, AIR_DENSITY, G = 0.65, 0.012, 1.2, 9.81
FRONT_OVERHANG_M = 3.65  # ego origin (rear axle) to front bumper
LANE_HALF_WIDTH_M = 1.75


def pedals(speed, accel):
    """Throttle and brake in 0..1 for an acceleration at a speed (the vehicle model inverted)."""
    resistance = ROLLING * MASS_KG * G + 0.5 * AIR_DENSITY * DRAG_AREA_M2 * speed * speed
    needed = MASS_KG * accel + resistance
    if needed >= 0:
        limit = min(MAX_FORCE_N, MAX_POWER_W / max(speed, 1.0))
        return min(needed / limit, 1.0), 0.0
    return 0.0, min(-needed / (MASS_KG * MAX_BRAKE_MPS2), 1.0)


def lead_of(objects):
    """(gap bumper to bumper, relative speed) of the nearest object ahead in the ego's lane."""
    ahead = [o for o in objects
             if o["position_in_ego_m"][0] > 0 and abs(o["position_in_ego_m"][1]) < LANE_HALF_WIDTH_M]
    if not ahead:
        return None
    o = min(ahead, key=lambda o: o["position_in_ego_m"][0])
    return o["position_in_ego_m"][0] - FRONT_OVERHANG_M, o["velocity_in_ego_mps"][0]


def target_accel(speed, lead, set_speed, time_gap, standstill_m=5.0):
    accel = 0.4 * (set_speed - speed)
    if lead is not None:
        gap, closing = lead
        desired = standstill_m + time_gap * speed
        accel = min(accel, 0.2 * (gap - desired) + 0.8 * closing)
    return max(-5.0, min(2.0, accel))


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--set-speed", type=float, default=30.0, help="cruise speed, m/s [default: 30]")
    parser.add_argument("--time-gap", type=float, default=1.8, help="time gap to a lead, s [default: 1.8]")
    parser.add_argument("--name", default="py-cruise", help="node name (liveliness, attachment) [default: py-cruise]")
    parser.add_argument("--duration", type=float, default=0, help="stop after S seconds of wall time [default: never]")
    connect.add_args(parser)
    args = parser.parse_args()
    if not (0 < args.set_speed < 70 and 0.5 <= args.time_gap <= 5):
        raise SystemExit("--set-speed must be in 0..70 m/s and --time-gap in 0.5..5 s")
    session, topics = cli.open_session(args)
    lock = threading.Lock()
    state = {"lead": None, "objects_at": 0.0, "seq": 0, "sent": 0}
    bad = BadPayloads()
    control = session.declare_publisher(topics.key("vehicle/control"))
    token = session.liveliness().declare_token(topics.node_key(args.name))
    attachment = args.name.encode()

    def on_objects(sample):
        try:
            _, _, gt = decode(sample.payload.to_bytes(), expected="GroundTruthObjects")
        except WireError as e:
            return bad("objects", e)
        with lock:
            state["lead"], state["objects_at"] = lead_of(gt["objects"]), time.monotonic()

    def on_speed(sample):
        try:
            _, header, speed = decode(sample.payload.to_bytes(), expected="Speed")
        except WireError as e:
            return bad("vehicle/speed", e)
        v = speed["speed_mps"]
        with lock:
            # Objects older than half a second are not trusted: hold speed carefully instead.
            fresh = time.monotonic() - state["objects_at"] < 0.5
            lead = state["lead"] if fresh else None
            seq = state["seq"]
            state["seq"] += 1
        accel = target_accel(v, lead, args.set_speed, args.time_gap)
        if not fresh:
            accel = min(accel, 0.0)
        throttle, brake = pedals(v, accel)
        command = {"throttle": throttle, "brake": brake, "steer": 0.0, "answers_step": None,
                   "perception_stamp_pub_ns": None}
        stamp = {"seq": seq, "stamp_sim_ns": header["stamp_sim_ns"], "stamp_pub_ns": time.time_ns()}
        control.put(encode("ControlCommand", stamp, command), attachment=attachment)
        with lock:
            state["sent"] += 1
        if seq % 100 == 0:
            gap = f"{lead[0]:6.1f} m" if lead else "  none "
            print(f"t={header['stamp_sim_ns'] / 1e9:8.2f} s  speed {v:5.2f} m/s  lead gap {gap}  "
                  f"accel {accel:+5.2f}  throttle {throttle:.2f} brake {brake:.2f}", flush=True)

    subs = [session.declare_subscriber(topics.key("objects"), on_objects),
            session.declare_subscriber(topics.key("vehicle/speed"), on_speed)]
    print(f"# {args.name}: {topics.key('vehicle/speed')} + {topics.key('objects')} -> {topics.key('vehicle/control')}",
          flush=True)
    end = time.monotonic() + args.duration if args.duration else math.inf
    try:
        while time.monotonic() < end:
            time.sleep(0.1)
    except KeyboardInterrupt:
        pass
    finally:
        for s in subs:
            s.undeclare()
        token.undeclare()
        control.undeclare()
        session.close()
        print(f"# sent {state['sent']} commands, {bad.count} undecodable payloads", flush=True)


if __name__ == "__main__":
    main()
