#!/usr/bin/env python3
"""An adaptive cruise controller of your own, in Python, as one function: the SDK
(slipstream_client.controller) does the rest of the node contract, lockstep included.

    slipstream up --controller "python3 clients/python/examples/own_acc.py"
    slipstream eval acc --perception ground-truth --controller "python3 clients/python/examples/own_acc.py"

Holds the driver's set speed, or the time gap behind the nearest vehicle in the ego's lane
(a constant-time-gap law on gap and closing speed), within comfort limits of acceleration and
jerk; brakes hard when the time to collision gets short. A teaching example, judged in docs/own-node.md beside
slipstream-acc: no estimator, no cut-in prediction, no lane map."""

import _path  # noqa: F401  (source checkout)

from slipstream_client.controller import Decision, run_controller

LANE_HALF_WIDTH_M = 1.75
STANDSTILL_GAP_M = 5.0
MAX_ACCEL, COMFORT_DECEL, EMERGENCY_DECEL = 1.5, -3.0, -8.0
EMERGENCY_TTC_S = 1.5
MAX_JERK = 2.0
last = {"t_s": None, "accel": 0.0}


def control(ego, ahead, settings):
    accel = 0.4 * (settings.set_speed_mps - ego.speed_mps)
    in_lane = [a for a in ahead if a.gap_m > 0 and abs(a.lateral_m) < LANE_HALF_WIDTH_M]
    lead = min(in_lane, key=lambda a: a.gap_m, default=None)
    if lead is not None:
        closing = -lead.relative_speed_mps
        if closing > 0 and lead.gap_m / closing < EMERGENCY_TTC_S:
            last["t_s"], last["accel"] = ego.t_s, EMERGENCY_DECEL
            return Decision(EMERGENCY_DECEL, lead=lead, emergency=True)
        desired = STANDSTILL_GAP_M + settings.time_gap_s * ego.speed_mps
        accel = min(accel, 0.25 * (lead.gap_m - desired) - 0.7 * closing)
    accel = max(COMFORT_DECEL, min(MAX_ACCEL, accel))
    # Comfort: the acceleration changes by at most MAX_JERK per second.
    step = MAX_JERK * (ego.t_s - last["t_s"]) if last["t_s"] is not None else 0.0
    accel = max(last["accel"] - step, min(last["accel"] + step, accel))
    last["t_s"], last["accel"] = ego.t_s, accel
    return Decision(accel, lead=lead)


if __name__ == "__main__":
    run_controller(control, description=__doc__)
