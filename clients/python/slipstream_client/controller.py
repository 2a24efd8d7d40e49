"""A controller of your own as one function; this module keeps the rest of the node contract
(docs/node-contract.md): it reads vehicle/state, the objects ahead (the detector's, or ground
truth when the run says so), the driver's settings (sim/ego, then acc/command) and the camera's
rate; answers every state with a ControlCommand naming its step and copying its stamp; waits,
on a step that brought a camera frame, for that frame's objects (so a lockstep run is the same
every time); publishes acc/status, which the judge reads; and declares the node's liveliness
token once it listens.

    from slipstream_client.controller import run_controller

    def control(ego, ahead, settings):          # -> an acceleration, m/s2 (or a Decision)
        return 0.5 * (settings.set_speed_mps - ego.speed_mps)

    run_controller(control)

It runs as `slipstream up --controller "python3 my_acc.py"` starts it (its connection and name
in SLIPSTREAM_ZENOH_CONFIG, SLIPSTREAM_NAMESPACE, SLIPSTREAM_NODE, the run in SLIPSTREAM_CLOCK and
SLIPSTREAM_PERCEPTION), or by hand with the usual connection flags.
"""

import argparse
import math
import os
import queue
import threading
import time
from dataclasses import dataclass, field, replace
from typing import Any, Callable, Dict, List, Optional, Tuple, Union

import zenoh

from . import cli, connect
from .wire import BadPayloads, WireError, decode, encode, encoding_schema

# How long an answer waits for its frame's objects: in lockstep (the run must not depend on
# timing) as long as slipstream-acc does; otherwise briefly, then with the objects there are.
LOCKSTEP_WAIT_S = 1.0
REALTIME_WAIT_S = 0.02
STATUS_HZ = 20.0
STANDSTILL_GAP_M = 5.0
DEFAULT_TIME_GAP_S = 1.8
AIR_DENSITY = 1.2
G = 9.81


@dataclass
class Ego:
    t_s: float
    step: int
    speed_mps: float
    accel_mps2: float
    yaw_rate_radps: float


@dataclass
class Ahead:
    """A vehicle ahead: gap from the ego's front bumper to its rear, its centre's lateral
    offset (positive left) and its speed relative to the ego's (negative: closing in)."""
    id: int
    gap_m: float
    lateral_m: float
    relative_speed_mps: float
    brake_lights: bool


@dataclass
class Settings:
    """The driver's settings (sim/ego at the start, acc/command after) and the vehicle (the
    EgoInfo body, docs/wire-format.md)."""
    set_speed_mps: float = 0.0
    time_gap_s: float = DEFAULT_TIME_GAP_S
    enabled: bool = True
    vehicle: Dict[str, Any] = field(default_factory=dict)


@dataclass
class Decision:
    """What `control` may return instead of a bare acceleration: the lead it follows (for
    acc/status and the judge's lead figures) and whether this is an emergency brake."""
    accel_mps2: float
    lead: Optional[Ahead] = None
    emergency: bool = False


Control = Callable[[Ego, List[Ahead], Settings], Union[float, Decision]]


def pedals(vehicle: Dict[str, Any], speed: float, accel: float) -> Tuple[float, float]:
    """Throttle and brake in 0..1 for an acceleration at a speed: the EgoInfo model inverted."""
    if not vehicle:
        return (min(max(accel / 3.0, 0.0), 1.0), min(max(-accel / 9.0, 0.0), 1.0))
    mass = vehicle["mass_kg"]
    resistance = vehicle["rolling_coeff"] * mass * G + 0.5 * AIR_DENSITY * vehicle["drag_area_m2"] * speed * speed
    needed = mass * accel + resistance
    if needed >= 0:
        limit = min(vehicle["max_drive_force_n"], vehicle["max_power_w"] / max(speed, 1.0))
        return min(needed / limit, 1.0), 0.0
    return 0.0, min(-needed / (mass * vehicle["max_brake_decel_mps2"]), 1.0)


def due(k: int, rate_hz: float, physics_hz: float) -> bool:
    """The clock contract: a publisher of `rate_hz` is due at step k (step 0, then whenever
    floor(t * rate) moves on)."""
    tick = lambda k: math.floor(k * rate_hz / physics_hz + 1e-9)  # noqa: E731
    return k == 0 or tick(k) > tick(k - 1)


class _Inputs:
    """What the callbacks bring, under one lock; `seen` wakes the answer waiting for a frame."""

    # self.ahead holds each object's distance from the ego's origin in gap_m until an answer
    # takes it (the vehicle's front overhang may come after the first objects).
    def __init__(self, ground_truth: bool, front_m: float) -> None:
        self.seen = threading.Condition()
        self.ground_truth = ground_truth
        self.settings = Settings()
        self.front_m = front_m
        self.rate_hz: Optional[float] = None
        self.physics_hz: Optional[float] = None
        self.ahead: List[Ahead] = []
        self.ahead_stamp_ns: Optional[int] = None
        self.ahead_pub_ns: Optional[int] = None

    def objects(self, header: Dict[str, int], body: Dict[str, Any]) -> None:
        if self.ground_truth:
            ahead = [Ahead(o["id"], o["position_in_ego_m"][0], o["position_in_ego_m"][1],
                           o["velocity_in_ego_mps"][0], o["brake_lights"])
                     for o in body["objects"] if o["position_in_ego_m"][0] > 0]
        else:
            ahead = [Ahead(d["track_id"], d["distance_m"], d["lateral_offset_m"],
                           d["relative_speed_mps"], d["brake_lights"]) for d in body["detections"]]
        with self.seen:
            if self.ahead_stamp_ns is None or header["stamp_sim_ns"] >= self.ahead_stamp_ns:
                self.ahead, self.ahead_stamp_ns = ahead, header["stamp_sim_ns"]
                self.ahead_pub_ns = header["stamp_pub_ns"]
            self.seen.notify_all()

    def ego(self, body: Dict[str, Any]) -> None:
        with self.seen:
            self.front_m = body["size_m"][0] - body["rear_overhang_m"]
            s = self.settings
            s.vehicle, s.set_speed_mps = body, body["set_speed_mps"]
            s.time_gap_s = body["time_gap_s"] or s.time_gap_s

    def command(self, body: Dict[str, Any]) -> None:
        with self.seen:
            s = self.settings
            s.enabled = s.enabled if body["enable"] is None else body["enable"]
            s.set_speed_mps = s.set_speed_mps if body["set_speed_mps"] is None else body["set_speed_mps"]
            s.time_gap_s = s.time_gap_s if body["time_gap_s"] is None else body["time_gap_s"]

    def frame_due(self, step: int, t_ns: int) -> bool:
        """Whether the state of `step` came with a camera frame whose objects are still to come."""
        if self.ahead_stamp_ns is not None and self.ahead_stamp_ns >= t_ns:
            return False
        if self.rate_hz is None or self.physics_hz is None:
            return self.ahead_stamp_ns is None  # before the rates are known: the first frame, at step 0
        return due(step, self.rate_hz, self.physics_hz)

    def known(self) -> bool:
        """The latched inputs an answer depends on are in: the vehicle and the camera's rate."""
        return bool(self.settings.vehicle) and self.rate_hz is not None


class ControllerNode:
    """The node around a `control` function (see the module doc). `start()` declares
    everything, then the token; `run(stop)` answers until `stop` is set."""

    def __init__(self, session: zenoh.Session, topics: Any, control: Control, name: str,
                 clock: str = "realtime", perception: str = "camera") -> None:
        self.session, self.topics, self.control, self.name = session, topics, control, name
        self.lockstep = clock == "lockstep"
        self.inputs = _Inputs(perception == "ground-truth", front_m=0.0)
        self.states: "queue.Queue[Tuple[Dict[str, int], Dict[str, Any]]]" = queue.Queue()
        self.bad = BadPayloads()
        self.answered = 0
        self.seq = {"vehicle/control": 0, "acc/status": 0}
        self.status_tick: Optional[int] = None
        self.latched_waited = False
        self.subs: List[Any] = []
        self.pubs: Dict[str, Any] = {}
        self.token: Any = None

    def _on(self, key: str, kind: str, then: Callable[[Dict[str, int], Dict[str, Any]], None]) -> Callable:
        def on_sample(sample: zenoh.Sample) -> None:
            try:
                _, header, body = decode(sample.payload.to_bytes(), expected=kind)
            except WireError as e:
                return self.bad(key, e)
            then(header, body)
        return on_sample

    def start(self) -> None:
        t, i = self.topics, self.inputs
        objects = ("objects", "GroundTruthObjects") if i.ground_truth else ("perception/objects", "Detections")
        plain = [("vehicle/state", "VehicleState", lambda h, b: self.states.put((h, b))),
                 (objects[0], objects[1], i.objects),
                 ("acc/command", "AccCommand", lambda h, b: i.command(b)),
                 ("sim/clock", "SimClock", lambda h, b: self._set(physics_hz=b["physics_hz"]))]
        for key, kind, then in plain:
            self.subs.append(self.session.declare_subscriber(t.key(key), self._on(key, kind, then)))
        latched = [("sim/ego", "EgoInfo", lambda h, b: i.ego(b)),
                   ("camera/front/info", "CameraInfo", lambda h, b: self._set(rate_hz=b["rate_hz"]))]
        for key, kind, then in latched:
            self.subs.append(zenoh.ext.declare_advanced_subscriber(
                self.session, t.key(key), self._on(key, kind, then),
                history=zenoh.ext.HistoryConfig(detect_late_publishers=True, max_samples=1)))
        self.pubs["vehicle/control"] = self.session.declare_publisher(
            t.key("vehicle/control"), express=True, priority=zenoh.Priority.REAL_TIME)
        self.pubs["acc/status"] = self.session.declare_publisher(t.key("acc/status"))
        self.token = self.session.liveliness().declare_token(t.node_key(self.name))

    def _set(self, **values: float) -> None:
        with self.inputs.seen:
            for k, v in values.items():
                setattr(self.inputs, k, v)
            self.inputs.seen.notify_all()

    def run(self, stop: threading.Event) -> int:
        while not stop.is_set():
            try:
                header, state = self.states.get(timeout=0.1)
            except queue.Empty:
                continue
            self.answer(header, state)
        return self.answered

    def _wait(self, ready: Callable[[], bool], wait_s: float) -> bool:
        with self.inputs.seen:
            return self.inputs.seen.wait_for(ready, timeout=wait_s)

    def answer(self, header: Dict[str, int], state: Dict[str, Any]) -> None:
        i, t_ns, step = self.inputs, header["stamp_sim_ns"], state["step"]
        if not self.latched_waited:
            self.latched_waited = True
            self._wait(i.known, LOCKSTEP_WAIT_S)
        if i.physics_hz is None and step > 0 and t_ns > 0:
            i.physics_hz = float(round(step * 1e9 / t_ns))
        if i.frame_due(step, t_ns):
            got = self._wait(lambda: i.ahead_stamp_ns is not None and i.ahead_stamp_ns >= t_ns,
                             LOCKSTEP_WAIT_S if self.lockstep else REALTIME_WAIT_S)
            if not got and self.lockstep:
                self.bad("perception", WireError(f"no objects for the frame at {t_ns / 1e9:.3f} s within 1 s"))
        with i.seen:
            ahead = [replace(a, gap_m=a.gap_m - i.front_m) for a in i.ahead]
            settings, pub_ns = i.settings, i.ahead_pub_ns
        ego = Ego(t_ns / 1e9, step, state["speed_mps"], state["acceleration_in_body_mps2"][0], state["yaw_rate_radps"])
        out = self.control(ego, ahead, settings) if settings.enabled else 0.0
        decision = out if isinstance(out, Decision) else Decision(float(out))
        throttle, brake = pedals(settings.vehicle, ego.speed_mps, decision.accel_mps2)
        if not settings.enabled:
            throttle, brake = 0.0, 0.0
        self._put("vehicle/control", "ControlCommand", t_ns,
                  {"throttle": throttle, "brake": brake, "steer": 0.0, "answers_step": step,
                   "perception_stamp_pub_ns": pub_ns})
        self.answered += 1
        self._status(ego, settings, decision)

    def _status(self, ego: Ego, settings: Settings, d: Decision) -> None:
        tick = math.floor(ego.t_s * STATUS_HZ + 1e-9)
        if tick == self.status_tick:
            return
        self.status_tick = tick
        mode = "Off" if not settings.enabled else "Emergency" if d.emergency else "Follow" if d.lead else "Speed"
        lead = None
        if d.lead is not None:
            closing = -d.lead.relative_speed_mps
            lead = {"id": d.lead.id, "gap_m": d.lead.gap_m,
                    "desired_gap_m": STANDSTILL_GAP_M + settings.time_gap_s * ego.speed_mps,
                    "relative_speed_mps": d.lead.relative_speed_mps,
                    "ttc_s": d.lead.gap_m / closing if closing > 0 else None}
        self._put("acc/status", "AccStatus", int(round(ego.t_s * 1e9)),
                  {"mode": mode, "set_speed_mps": settings.set_speed_mps, "time_gap_s": settings.time_gap_s,
                   "target_accel_mps2": d.accel_mps2, "lead": lead,
                   "warnings": ["ForwardCollision"] if d.emergency else []})

    def _put(self, key: str, kind: str, t_ns: int, body: Dict[str, Any]) -> None:
        seq = self.seq[key]
        self.seq[key] += 1
        header = {"seq": seq, "stamp_sim_ns": t_ns, "stamp_pub_ns": time.time_ns()}
        self.pubs[key].put(encode(kind, header, body), attachment=self.name.encode(),
                           encoding=zenoh.Encoding.APPLICATION_OCTET_STREAM.with_schema(encoding_schema(kind)))

    def close(self) -> None:
        if self.token is not None:
            self.token.undeclare()
        for s in self.subs:
            s.undeclare()
        for p in self.pubs.values():
            p.undeclare()


def run_controller(control: Control, description: Optional[str] = None,
                   parser: Optional[argparse.ArgumentParser] = None) -> argparse.Namespace:
    """Runs `control` as the loop's controller until Ctrl-C or SIGTERM; returns the parsed flags
    (give `parser` to add flags of your own; read them inside `control` through a closure)."""
    parser = parser or argparse.ArgumentParser(description=description)
    parser.add_argument("--name", default=os.environ.get("SLIPSTREAM_NODE", "acc"),
                        help="node name (liveliness, attachment) [env: SLIPSTREAM_NODE; default: acc]")
    parser.add_argument("--clock", choices=["realtime", "fast", "lockstep"],
                        default=os.environ.get("SLIPSTREAM_CLOCK", "realtime"),
                        help="the simulator's clock [env: SLIPSTREAM_CLOCK; default: realtime]")
    parser.add_argument("--perception", choices=["camera", "ground-truth"],
                        default=os.environ.get("SLIPSTREAM_PERCEPTION", "camera"),
                        help="objects from the detector or the simulator's ground truth "
                             "[env: SLIPSTREAM_PERCEPTION; default: camera]")
    connect.add_args(parser)
    args = parser.parse_args()
    session, topics = cli.open_session(args)
    node = ControllerNode(session, topics, control, args.name, args.clock, args.perception)
    cli.serve(node, session, lambda: f"# {args.name}: {node.answered} commands, "
                                     f"{node.bad.count} undecodable or missing inputs")
    return args
