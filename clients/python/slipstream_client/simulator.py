"""The simulator's side of slipstream's contract (docs/simulator-contract.md) on a Zenoh
session, for any simulator written in Python: the reference simulator, the CARLA and the
CoppeliaSim adapters. The simulator brings its world; this brings the bus:

    side = SimulatorSide(session, topics, mode="lockstep", physics_hz=100)
    side.start(camera_info, road)                  # latched info and road, ScenarioStart, lockstep start
    for k in range(steps):
        side.publish_ego(k, speed_mps, state, rtf)  # vehicle/speed, vehicle/state, sim/clock
        side.publish_frame(k, frame, objects)       # on camera steps
        command = side.control(k)                   # the ego's input for step k -> k + 1, or None
        ...step the world with it...
    side.end(steps, "duration reached")

Publishers carry the contract's QoS, headers (seq per publisher, t_k = floor(k * 1e9 /
physics_hz)), Zenoh encodings and the attachment `sim`; camera info and road are latched.
vehicle/control follows one controller (the first that names itself; another after 2 s of
silence), holds a command 200 ms of simulated time, then brakes 0.4. In lockstep, `control(k)`
waits for every awaited node's answer to step k (at most `step_timeout` s, then a
ControlTimeout event and a brake)."""

import threading
import time
from typing import Any, Dict, List, Optional, Sequence, Tuple

import zenoh
import zenoh.ext

from .keys import Topics
from .wire import BadPayloads, WireError, decode, encode, encoding_schema

NEUTRAL = {"throttle": 0.0, "brake": 0.0, "steer": 0.0, "answers_step": None, "perception_stamp_pub_ns": None}
HOLD_S, TIMEOUT_BRAKE, SWITCH_AFTER_S = 0.2, 0.4, 2.0
MODES = ("realtime", "fast", "lockstep")

# Topic -> (priority, express, congestion control): the contract's QoS.
_QOS = {
    "vehicle/speed": (zenoh.Priority.REAL_TIME, True, zenoh.CongestionControl.BLOCK),
    "vehicle/state": (zenoh.Priority.INTERACTIVE_HIGH, True, zenoh.CongestionControl.BLOCK),
    "sim/clock": (zenoh.Priority.REAL_TIME, True, zenoh.CongestionControl.BLOCK),
    "objects": (zenoh.Priority.DATA, True, zenoh.CongestionControl.BLOCK),
    "sim/events": (zenoh.Priority.DATA, False, zenoh.CongestionControl.BLOCK),
    "camera/front": (zenoh.Priority.DATA_LOW, False, zenoh.CongestionControl.DROP),
}
_LATCHED = ("camera/front/info", "sim/road", "sim/ego")


class RealTimeFactor:
    """Simulated seconds per wall-clock second over the last wall-clock second."""

    def __init__(self):
        self.window = []

    def __call__(self, sim_s):
        now = time.monotonic()
        self.window = [w for w in self.window if now - w[0] <= 1.0] + [(now, sim_s)]
        (t0, s0), (t1, s1) = self.window[0], self.window[-1]
        return (s1 - s0) / (t1 - t0) if t1 > t0 else 0.0


class SimulatorSide:
    """One simulator on the bus (see the module's doc)."""

    def __init__(self, session: zenoh.Session, topics: Topics, mode: str, physics_hz: int,
                 wait_for: Sequence[str] = ("acc",), step_timeout: float = 2.0, name: str = "sim") -> None:
        if mode not in MODES:
            raise ValueError(f"mode {mode!r}: use one of {', '.join(MODES)}")
        self.session, self.topics, self.mode, self.hz = session, topics, mode, int(physics_hz)
        self.wait_for, self.step_timeout, self.name = list(wait_for), step_timeout, name
        self.attachment = name.encode()
        self.seq: Dict[str, int] = {}
        self.bad = BadPayloads()
        self.arrived = threading.Condition()
        # The followed controller's newest command: (command, header, arrival ns, sim ns then).
        self.latest: Optional[Tuple[Dict[str, Any], Dict[str, int], int, int]] = None
        self.answers: Dict[Tuple[str, int], Tuple[Dict[str, Any], Dict[str, int]]] = {}
        self.followed: Optional[str] = None
        self.heard, self.now_ns = 0.0, 0
        self.applied: Dict[str, Any] = dict(NEUTRAL)
        self.timing: Optional[Dict[str, int]] = None
        self.pubs = {t: session.declare_publisher(topics.key(t), priority=p, express=e, congestion_control=c)
                     for t, (p, e, c) in _QOS.items()}
        self.pubs.update({t: self.latched(t) for t in _LATCHED})
        self.control_sub = session.declare_subscriber(topics.key("vehicle/control"), self.on_control)
        self.token = session.liveliness().declare_token(topics.node_key(name))

    def latched(self, topic: str) -> Any:
        """A publisher whose last sample a late subscriber still gets (zenoh-ext's cache)."""
        return zenoh.ext.declare_advanced_publisher(
            self.session, self.topics.key(topic), cache=zenoh.ext.CacheConfig(max_samples=1),
            sample_miss_detection=zenoh.ext.MissDetectionConfig(),  # type: ignore[call-arg]  # defaults in 1.10
            publisher_detection=True)

    def stamp(self, k: int) -> int:
        """Step k's simulated time, ns: floor(k * 1e9 / physics_hz)."""
        return k * 1_000_000_000 // self.hz

    def put(self, topic: str, kind: str, k: int, body: Dict[str, Any]) -> None:
        seq = self.seq[topic] = self.seq.get(topic, -1) + 1
        header = {"seq": seq, "stamp_sim_ns": self.stamp(k), "stamp_pub_ns": time.time_ns()}
        self.pubs[topic].put(encode(kind, header, body), attachment=self.attachment,
                             encoding=zenoh.Encoding.APPLICATION_OCTET_STREAM.with_schema(encoding_schema(kind)))

    def start(self, camera_info: Dict[str, Any], road: Optional[Dict[str, Any]] = None, scenario: str = "external",
              seed: int = 0, ego: Optional[Dict[str, Any]] = None) -> None:
        """Camera info, road and ego (an EgoInfo body: the vehicle and the driver's settings),
        latched; ScenarioStart; in lockstep, the awaited controllers."""
        self.put("camera/front/info", "CameraInfo", 0, camera_info)
        if road is not None:
            self.put("sim/road", "RoadMap", 0, road)
        if ego is not None:
            self.put("sim/ego", "EgoInfo", 0, ego)
        self.put("sim/events", "SimEvent", 0, {"kind": {"variant": "ScenarioStart", "name": scenario, "seed": seed}})
        if self.mode == "lockstep":
            self.wait_for_controllers()

    def publish_ego(self, k: int, speed_mps: float, state: Dict[str, Any], rtf: float) -> None:
        """vehicle/speed, vehicle/state (`state` without step, applied and control_timing) and
        sim/clock for step k."""
        self.now_ns = self.stamp(k)
        self.put("vehicle/speed", "Speed", k, {"speed_mps": speed_mps})
        self.put("vehicle/state", "VehicleState", k,
                 {**state, "step": k, "applied": self.applied, "control_timing": self.timing})
        self.put("sim/clock", "SimClock", k, {"step": k, "real_time_factor": rtf, "mode": self.mode.capitalize(),
                                              "physics_hz": float(self.hz)})

    def publish_frame(self, k: int, frame: Dict[str, Any], objects: Optional[List[Dict[str, Any]]] = None) -> None:
        """camera/front (a CameraFrame body) and, when given, its ground truth (a list)."""
        self.put("camera/front", "CameraFrame", k, frame)
        if objects is not None:
            self.put("objects", "GroundTruthObjects", k, {"step": k, "objects": objects})

    def event(self, k: int, variant: str, **fields: Any) -> None:
        self.put("sim/events", "SimEvent", k, {"kind": {"variant": variant, **fields}})

    def end(self, k: int, reason: str, success: bool = True) -> None:
        self.event(k, "ScenarioEnd", reason=reason, success=success)

    def on_control(self, sample: Any) -> None:
        try:
            _, header, cmd = decode(sample.payload.to_bytes(), expected="ControlCommand")
        except WireError as e:
            return self.bad("vehicle/control", e)
        source = bytes(sample.attachment.to_bytes()).decode(errors="replace") if sample.attachment else None
        with self.arrived:
            if self.mode == "lockstep":
                if source in self.wait_for and cmd["answers_step"] is not None:
                    self.answers[(source, cmd["answers_step"])] = (cmd, header)
            else:
                silent = time.monotonic() - self.heard > SWITCH_AFTER_S
                if self.followed in (None, source) or silent:
                    self.followed, self.heard = source, time.monotonic()
                    self.latest = (cmd, header, time.time_ns(), self.now_ns)
            self.arrived.notify_all()

    def control(self, k: int) -> Optional[Dict[str, Any]]:
        """The ego's input from step k to k + 1: a ControlCommand dict, or None before the first
        command (the simulator decides: the reference simulator holds its speed). What it
        returns shows in the next state's `applied`."""
        cmd, self.timing = self.command_for(k)
        self.applied = cmd if cmd is not None else dict(NEUTRAL)
        return cmd

    def command_for(self, k: int) -> Tuple[Optional[Dict[str, Any]], Optional[Dict[str, int]]]:
        """(command or None, control_timing)."""
        if self.mode == "lockstep":
            return self.await_answer(k)
        with self.arrived:
            latest = self.latest
        if latest is None:
            return None, None
        cmd, header, arrived_ns, arrived_sim_ns = latest
        if self.stamp(k) - arrived_sim_ns > HOLD_S * 1e9:  # the controller went quiet: brake
            return {**NEUTRAL, "brake": TIMEOUT_BRAKE}, None
        return cmd, {"command_stamp_pub_ns": header["stamp_pub_ns"], "applied_ns": arrived_ns}

    def await_answer(self, k: int) -> Tuple[Optional[Dict[str, Any]], Optional[Dict[str, int]]]:
        """Lockstep: every awaited node's answer to step k, at most `step_timeout` seconds."""
        deadline = time.monotonic() + self.step_timeout
        with self.arrived:
            while not all((n, k) in self.answers for n in self.wait_for):
                left = deadline - time.monotonic()
                if left <= 0:
                    late = [n for n in self.wait_for if (n, k) not in self.answers]
                    self.event(k, "ControlTimeout", late=late)
                    return {**NEUTRAL, "brake": TIMEOUT_BRAKE}, None
                self.arrived.wait(min(left, 0.1))
            cmd, header = self.answers.pop((self.wait_for[0], k))
            self.answers = {key: v for key, v in self.answers.items() if key[1] > k}
        return cmd, {"command_stamp_pub_ns": header["stamp_pub_ns"], "applied_ns": time.time_ns()}

    def wait_for_controllers(self, timeout: float = 30.0) -> None:
        """Lockstep start: the awaited nodes' liveliness tokens, then a vehicle/state subscriber."""
        deadline = time.monotonic() + timeout
        wanted = {self.topics.node_key(n) for n in self.wait_for}
        while time.monotonic() < deadline:
            replies = self.session.liveliness().get(self.topics.node_key("*"), timeout=1)
            alive = {str(r.ok.key_expr) for r in replies if r.ok is not None}
            if wanted <= alive:
                while time.monotonic() < deadline and not self.pubs["vehicle/state"].matching_status.matching:  # type: ignore[attr-defined]
                    time.sleep(0.02)
                return
            time.sleep(0.1)
        raise TimeoutError(f"lockstep: {', '.join(self.wait_for)} not up after {timeout:.0f} s "
                           "(start the loop, e.g. `slipstream up --sim external --mode lockstep`)")

    def close(self) -> None:
        self.token.undeclare()
        self.control_sub.undeclare()

