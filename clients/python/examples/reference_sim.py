#!/usr/bin/env python3
"""A reference simulator in Python: the simulator side of slipstream's contract
(docs/simulator-contract.md), small enough to read in one sitting, that slipstream-detect and
slipstream-acc drive as they drive slipstream-sim.

    python3 clients/python/examples/reference_sim.py &            # realtime, 60 s
    target/release/slipstream conform sim                         # check it keeps the contract
    target/release/slipstream up --sim external                   # or close the loop around it

A straight three-lane road; the ego in the middle lane behind a car that slows from 22 to
12 m/s at 12 s and speeds up again at 25 s, a faster car in the left lane. Point-mass
longitudinal dynamics with the default car's numbers and a 0.3 s actuator lag (no steering). A pinhole camera drawn
with numpy: sky, grass, asphalt, dashed markings, each vehicle's rear as a box with its dark
contact band, windows and lamps (lit when it brakes). Publishes vehicle/speed, vehicle/state
and sim/clock every step, camera/front and objects (ground truth) at --camera-hz,
camera/front/info and sim/road latched, sim/events; applies vehicle/control. Clock modes:
realtime, fast, lockstep (--wait-for NODE: every step waits for that node's answer)."""

import argparse
import math
import threading
import time

import _path  # noqa: F401  (source checkout)
import numpy as np
import zenoh

from slipstream_client import BadPayloads, WireError, connect, decode, encode, encoding_schema

LANES, LANE_W = 3, 3.5
CAR_SIZE, CAR_REAR_OVERHANG = [4.6, 1.85, 1.45], 0.95
# Forward dynamics of the default car (the inverse is config/acc.json5's vehicle model).
MASS_KG, MAX_FORCE_N, MAX_POWER_W, MAX_BRAKE_MPS2 = 1500.0, 6500.0, 110000.0, 9.0
DRAG_AREA_M2, ROLLING, AIR_DENSITY, G = 0.65, 0.012, 1.2, 9.81
ACTUATOR_LAG_S = 0.3  # throttle and brake follow a command through a first-order lag
HOLD_S, TIMEOUT_BRAKE = 0.2, 0.4  # a command holds 200 ms of simulated time, then brake 0.4
SKY, GRASS, ASPHALT, MARKING = (150, 185, 220), (78, 118, 62), (84, 84, 88), (228, 228, 222)
CONTACT, GLASS, TAIL, BRAKE_LAMP = (24, 24, 26), (38, 50, 62), (205, 25, 25), (255, 42, 30)


def lane_d(lane):
    """Lateral offset of a lane's centre (lane 0 is the rightmost; the road is centred on 0)."""
    return (lane + 0.5 - LANES / 2) * LANE_W


class Vehicle:
    def __init__(self, vid, lane, s, speed, color, profile=None):
        self.id, self.lane, self.s, self.v, self.a = vid, lane, s, speed, 0.0
        self.color, self.profile, self.braking = color, profile, False

    def drive(self, t, dt):
        """Traffic: follow the speed profile [(from_t, target_mps, accel_mps2), ...]."""
        target, rate = self.v, 0.0
        for start, speed, accel in self.profile or []:
            if t >= start:
                target, rate = speed, accel
        self.a = max(-rate, min(rate, (target - self.v) / dt)) if rate else 0.0
        self.braking = self.a < -0.5
        self.v = max(0.0, self.v + self.a * dt)
        self.s += self.v * dt


class Camera:
    """A pinhole camera on the ego: 60 degrees wide, 1.35 m up, pitched 3 degrees down."""

    def __init__(self, width, height, rate_hz, fov_deg=60.0, mount=(1.6, 0.0, 1.35), pitch_deg=3.0):
        self.w, self.h, self.rate_hz, self.mount, self.pitch = width, height, rate_hz, mount, math.radians(pitch_deg)
        self.f = (width / 2) / math.tan(math.radians(fov_deg) / 2)
        self.info = {"width": width, "height": height, "fx_px": self.f, "fy_px": self.f, "cx_px": width / 2,
                     "cy_px": height / 2, "horizontal_fov_rad": math.radians(fov_deg),
                     "mount_position_in_ego_m": list(mount), "mount_roll_pitch_yaw_rad": [0.0, self.pitch, 0.0],
                     "rate_hz": rate_hz, "encoding": "Rgb8"}
        # Where each pixel's ray meets the ground (ego frame), once: the road is straight and
        # the ego keeps its lane, so only the dashes move.
        u, v = np.meshgrid(np.arange(width) + 0.5, np.arange(height) + 0.5)
        cp, sp = math.cos(self.pitch), math.sin(self.pitch)
        right, up = (u - width / 2) / self.f, (height / 2 - v) / self.f
        dx, dz = cp + up * sp, -sp + up * cp
        ground = dz < -1e-6
        t = np.where(ground, -mount[2] / np.where(ground, dz, -1.0), 0.0)
        self.gx, self.gy = mount[0] + t * dx, -t * right
        road = ground & (np.abs(self.gy) <= LANES * LANE_W / 2) & (self.gx < 400)
        self.base = np.empty((height, width, 3), np.uint8)
        self.base[:] = SKY
        self.base[ground] = GRASS
        self.base[road] = ASPHALT
        lines = [lane_d(i) + LANE_W / 2 for i in range(LANES - 1)]
        self.marking = road & (np.min([np.abs(self.gy - y) for y in lines], axis=0) < 0.075) & (self.gx < 160)

    def project(self, x, y, z):
        """Pixel (u, v) of a point in the ego frame, or None behind the camera."""
        px, pz = x - self.mount[0], z - self.mount[2]
        depth = px * math.cos(self.pitch) - pz * math.sin(self.pitch)
        if depth < 0.5:
            return None
        up = px * math.sin(self.pitch) + pz * math.cos(self.pitch)
        return self.w / 2 - self.f * (y - self.mount[1]) / depth, self.h / 2 - self.f * up / depth

    def render(self, ego_s, others):
        """The frame (H x W x 3 RGB8) and each vehicle's (bbox, visible fraction)."""
        img = self.base.copy()
        img[self.marking & (((self.gx + ego_s) % 12.0) < 3.0)] = MARKING
        boxes = {}
        for o in sorted(others, key=lambda o: -o["x"]):  # far to near
            boxes[o["id"]] = self.draw(img, o)
        return img, boxes

    def draw(self, img, o):
        half_w, height = CAR_SIZE[1] / 2, CAR_SIZE[2]
        a, b = self.project(o["x"], o["y"] + half_w, height), self.project(o["x"], o["y"] - half_w, 0.0)
        if a is None or b is None:
            return None, 0.0
        (u0, v0), (u1, v1) = a, b
        area = max((u1 - u0) * (v1 - v0), 1e-9)
        cu0, cv0, cu1, cv1 = max(u0, 0), max(v0, 0), min(u1, self.w), min(v1, self.h)
        if cu1 <= cu0 or cv1 <= cv0:
            return None, 0.0
        bottom = math.floor(v1)  # the row the contact line crosses: covered v1 - bottom
        rows = lambda f0, f1: slice(int(round(v1 - f1 * (v1 - v0))), bottom if f0 == 0 else int(round(v1 - f0 * (v1 - v0))))
        cols = slice(int(round(u0)), int(round(u1)))
        span = lambda s: slice(max(s.start, 0), max(s.stop, 0))
        img[span(rows(0.0, 1.0)), span(cols)] = o["color"]
        img[span(rows(0.55, 0.85)), span(cols)] = GLASS
        img[span(rows(0.0, 0.22)), span(cols)] = CONTACT
        if 0 <= bottom < self.h:  # anti-aliased: the detector places the contact line inside a row
            cover = v1 - bottom
            edge = img[bottom, span(cols)].astype(np.float32)
            img[bottom, span(cols)] = (edge * (1 - cover) + np.array(CONTACT, np.float32) * cover).astype(np.uint8)
        lamp_w = max(1, int((u1 - u0) * 0.15))
        lamp = BRAKE_LAMP if o["braking"] else TAIL
        for c in (slice(int(u0), int(u0) + lamp_w), slice(int(u1) - lamp_w, int(u1))):
            img[span(rows(0.35, 0.45)), span(c)] = lamp
        bbox = {"u_min_px": cu0, "v_min_px": cv0, "u_max_px": cu1, "v_max_px": cv1}
        return bbox, (cu1 - cu0) * (cv1 - cv0) / area


class ReferenceSim:
    """One simulator on the bus. Each method is one part of the contract."""

    def __init__(self, session, topics, args):
        self.session, self.topics, self.args = session, topics, args
        self.hz = args.physics_hz
        self.camera = Camera(*args.camera_size, args.camera_hz)
        self.ego = Vehicle(0, 1, 0.0, 25.0, None)
        self.traffic = [Vehicle(1, 1, 45.0, 22.0, (150, 32, 36), [(12, 12.0, 3.0), (25, 22.0, 1.0)]),
                        Vehicle(2, 2, 75.0, 26.0, (40, 70, 160))]
        self.lock, self.arrived = threading.Lock(), threading.Condition()
        self.latest, self.answers, self.followed, self.now_ns = None, {}, None, 0
        self.seq, self.bad = {}, BadPayloads()
        # Throttle and brake as the actuators have them; at the start, what holds 25 m/s.
        self.pedals = [(ROLLING * MASS_KG * G + 0.5 * AIR_DENSITY * DRAG_AREA_M2 * 625) / min(MAX_FORCE_N, MAX_POWER_W / 25), 0.0]
        self.pubs = {}
        prio, low = zenoh.Priority.REAL_TIME, zenoh.Priority.DATA_LOW
        for topic, priority, express in [("vehicle/speed", prio, True), ("vehicle/state", zenoh.Priority.INTERACTIVE_HIGH, True),
                                         ("sim/clock", prio, True), ("objects", None, True), ("sim/events", None, False)]:
            self.pubs[topic] = session.declare_publisher(topics.key(topic), priority=priority, express=express,
                                                         congestion_control=zenoh.CongestionControl.BLOCK)
        self.pubs["camera/front"] = session.declare_publisher(topics.key("camera/front"), priority=low,
                                                              congestion_control=zenoh.CongestionControl.DROP)
        for topic in ("camera/front/info", "sim/road"):
            self.pubs[topic] = self.latched(topic)
        self.control_sub = session.declare_subscriber(topics.key("vehicle/control"), self.on_control)
        self.token = session.liveliness().declare_token(topics.node_key("sim"))

    def latched(self, topic):
        """A publisher whose last sample a late subscriber still gets (zenoh-ext's cache)."""
        return zenoh.ext.declare_advanced_publisher(
            self.session, self.topics.key(topic), cache=zenoh.ext.CacheConfig(max_samples=1),
            sample_miss_detection=zenoh.ext.MissDetectionConfig(), publisher_detection=True)

    def stamp(self, k):
        """Step k's simulated time, ns: floor(k * 1e9 / physics_hz)."""
        return k * 1_000_000_000 // self.hz

    def put(self, topic, kind, k, body):
        seq = self.seq[topic] = self.seq.get(topic, -1) + 1
        header = {"seq": seq, "stamp_sim_ns": self.stamp(k), "stamp_pub_ns": time.time_ns()}
        self.pubs[topic].put(encode(kind, header, body), attachment=b"sim",
                             encoding=zenoh.Encoding.APPLICATION_OCTET_STREAM.with_schema(encoding_schema(kind)))

    def on_control(self, sample):
        """vehicle/control: one controller at a time (the first that names itself)."""
        try:
            _, header, cmd = decode(sample.payload.to_bytes(), expected="ControlCommand")
        except WireError as e:
            return self.bad("vehicle/control", e)
        source = bytes(sample.attachment.to_bytes()).decode(errors="replace") if sample.attachment else None
        with self.arrived:
            if self.args.mode == "lockstep":
                if source in self.args.wait_for and cmd["answers_step"] is not None:
                    self.answers[(source, cmd["answers_step"])] = (cmd, header)
            elif self.followed in (None, source):
                self.followed = source
                self.latest = (cmd, header, time.time_ns(), self.now_ns)
            self.arrived.notify_all()

    def publish_start(self):
        self.put("camera/front/info", "CameraInfo", 0, self.camera.info)
        self.put("sim/road", "RoadMap", 0, {"lanes": LANES, "lane_width_m": LANE_W, "length_m": 5000.0,
                                            "curves": [], "lane_ends": []})
        self.put("sim/events", "SimEvent", 0, {"kind": {"variant": "ScenarioStart", "name": "reference", "seed": 0}})

    def publish_step(self, k, applied, timing, rtf):
        ego = self.ego
        self.put("vehicle/speed", "Speed", k, {"speed_mps": ego.v})
        self.put("vehicle/state", "VehicleState", k, {
            "step": k, "position_in_world_m": [ego.s, lane_d(ego.lane), 0.0], "yaw_in_world_rad": 0.0,
            "pitch_rad": 0.0, "roll_rad": 0.0, "velocity_in_world_mps": [ego.v, 0.0, 0.0],
            "acceleration_in_body_mps2": [ego.a, 0.0, 0.0], "yaw_rate_radps": 0.0, "speed_mps": ego.v,
            "lane": ego.lane, "applied": applied, "control_timing": timing})
        self.put("sim/clock", "SimClock", k, {"step": k, "real_time_factor": rtf, "mode": self.args.mode.capitalize(),
                                              "physics_hz": float(self.hz)})
        if k % round(self.hz / self.camera.rate_hz) == 0:
            self.publish_frame(k)

    def publish_frame(self, k):
        ego, front = self.ego, CAR_SIZE[0] - CAR_REAR_OVERHANG
        others = [{"id": v.id, "x": v.s - CAR_REAR_OVERHANG - ego.s, "y": lane_d(v.lane) - lane_d(ego.lane),
                   "color": v.color, "braking": v.braking} for v in self.traffic]
        img, boxes = self.camera.render(ego.s, [o for o in others if o["x"] > front])
        self.put("camera/front", "CameraFrame", k, {"width": self.camera.w, "height": self.camera.h,
                                                    "encoding": "Rgb8", "data": img.tobytes()})
        objects = []
        for v, o in zip(self.traffic, others):
            bbox, visible = boxes.get(v.id, (None, 0.0))
            objects.append({
                "id": v.id, "class": "Car", "size_m": CAR_SIZE, "lane": v.lane,
                "position_in_world_m": [v.s, lane_d(v.lane), 0.0], "yaw_in_world_rad": 0.0,
                "velocity_in_world_mps": [v.v, 0.0, 0.0], "position_in_ego_m": [o["x"], o["y"], CAR_SIZE[2] / 2],
                "yaw_in_ego_rad": 0.0, "velocity_in_ego_mps": [v.v - ego.v, 0.0, 0.0], "bbox": bbox,
                "visible_fraction": visible, "brake_lights": v.braking})
        self.put("objects", "GroundTruthObjects", k, {"step": k, "objects": objects})

    def command_for(self, k, t_ns):
        """The ego's input for step k -> k + 1: (command, control_timing) or None to cruise."""
        if self.args.mode == "lockstep":
            return self.await_answer(k)
        with self.arrived:
            latest = self.latest
        if latest is None:
            return None  # before the first command: hold the start speed
        cmd, header, arrived_ns, arrived_sim_ns = latest
        if t_ns - arrived_sim_ns > HOLD_S * 1e9:  # the controller went quiet: brake
            return {**NEUTRAL, "brake": TIMEOUT_BRAKE}, None
        return cmd, {"command_stamp_pub_ns": header["stamp_pub_ns"], "applied_ns": arrived_ns}

    def await_answer(self, k):
        """Lockstep: every --wait-for node's answer to step k, at most --step-timeout."""
        deadline = time.monotonic() + self.args.step_timeout
        with self.arrived:
            while not all((n, k) in self.answers for n in self.args.wait_for):
                left = deadline - time.monotonic()
                if left <= 0:
                    late = [n for n in self.args.wait_for if (n, k) not in self.answers]
                    self.put("sim/events", "SimEvent", k, {"kind": {"variant": "ControlTimeout", "late": late}})
                    return {**NEUTRAL, "brake": TIMEOUT_BRAKE}, None
                self.arrived.wait(min(left, 0.1))
            cmd, header = self.answers.pop((self.args.wait_for[0], k))
            self.answers = {key: v for key, v in self.answers.items() if key[1] > k}
        return cmd, {"command_stamp_pub_ns": header["stamp_pub_ns"], "applied_ns": time.time_ns()}

    def physics(self, t, dt, cmd):
        ego = self.ego
        if cmd is None:
            ego.a = 0.0
        else:
            lag = min(1.0, dt / ACTUATOR_LAG_S)
            self.pedals = [p + (c - p) * lag for p, c in zip(self.pedals, (cmd["throttle"], cmd["brake"]))]
            throttle, brake = self.pedals
            resistance = ROLLING * MASS_KG * G + 0.5 * AIR_DENSITY * DRAG_AREA_M2 * ego.v * ego.v
            drive = throttle * min(MAX_FORCE_N, MAX_POWER_W / max(ego.v, 1.0))
            ego.a = (drive - resistance) / MASS_KG - brake * MAX_BRAKE_MPS2
        ego.v = max(0.0, ego.v + ego.a * dt)
        ego.s += ego.v * dt
        for v in self.traffic:
            v.drive(t, dt)
            gap = v.s - CAR_REAR_OVERHANG - (ego.s + CAR_SIZE[0] - CAR_REAR_OVERHANG)
            if v.lane == ego.lane and gap < 0 and not getattr(v, "hit", False):
                v.hit = True
                self.put("sim/events", "SimEvent", round(t * self.hz),
                         {"kind": {"variant": "Collision", "other_id": v.id, "relative_speed_mps": ego.v - v.v}})

    def wait_for_controllers(self):
        """Lockstep: the awaited nodes' liveliness tokens, then a vehicle/state subscriber."""
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline:
            alive = {str(r.ok.key_expr) for r in self.session.liveliness().get(self.topics.node_key("*"), timeout=1)
                     if r.ok is not None}
            if all(self.topics.node_key(n) in alive for n in self.args.wait_for):
                while time.monotonic() < deadline and not self.pubs["vehicle/state"].matching_status.matching:
                    time.sleep(0.02)
                return
            time.sleep(0.1)
        raise RuntimeError(f"lockstep: {', '.join(self.args.wait_for)} not up after 30 s")

    def run(self, stop):
        self.publish_start()
        if self.args.mode == "lockstep":
            self.wait_for_controllers()
        dt, steps = 1.0 / self.hz, round(self.args.duration * self.hz)
        started, applied, timing = time.monotonic(), NEUTRAL, None
        window = [(started, 0)]
        for k in range(steps + 1):
            if stop.is_set():
                break
            now = time.monotonic()
            window = [w for w in window if now - w[0] <= 1.0] + [(now, k)]
            rtf = (k - window[0][1]) * dt / max(now - window[0][0], 1e-6) if len(window) > 1 else 0.0
            self.publish_step(k, applied, timing, rtf)
            if k == steps:
                break
            self.now_ns = self.stamp(k)
            chosen = self.command_for(k, self.now_ns)
            cmd, timing = chosen if chosen else (None, None)
            applied = cmd if cmd is not None else NEUTRAL
            self.physics(k * dt, dt, cmd)
            if self.args.mode == "realtime":
                time.sleep(max(0.0, started + (k + 1) * dt - time.monotonic()))
        end = "stopped" if stop.is_set() else "duration reached"
        self.put("sim/events", "SimEvent", k, {"kind": {"variant": "ScenarioEnd", "reason": end, "success": True}})
        return k


NEUTRAL = {"throttle": 0.0, "brake": 0.0, "steer": 0.0, "answers_step": None, "perception_stamp_pub_ns": None}


def size(text):
    w, _, h = text.partition("x")
    return int(w), int(h)


def parser():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--mode", choices=["realtime", "fast", "lockstep"], default="realtime", help="[default: realtime]")
    p.add_argument("--duration", type=float, default=60.0, help="simulated seconds [default: 60]")
    p.add_argument("--physics-hz", type=int, default=100, help="steps per simulated second [default: 100]")
    p.add_argument("--camera-hz", type=float, default=20.0, help="frames per simulated second [default: 20]")
    p.add_argument("--camera-size", type=size, default=(640, 480), help="WIDTHxHEIGHT [default: 640x480]")
    p.add_argument("--wait-for", action="append", metavar="NODE",
                   help="lockstep: the node(s) whose answer each step waits for [default: acc]")
    p.add_argument("--step-timeout", type=float, default=2.0, help="lockstep: seconds a step waits [default: 2]")
    connect.add_args(p)
    return p


def main(sim_class=ReferenceSim):
    args = parser().parse_args()
    args.wait_for = args.wait_for or ["acc"]
    if args.physics_hz % args.camera_hz or not 0 < args.camera_hz <= args.physics_hz:
        raise SystemExit("--camera-hz must divide --physics-hz")
    session, topics = connect.open_from_args(args)
    stop = threading.Event()
    sim = sim_class(session, topics, args)
    print(f"# reference simulator: {args.mode}, {args.duration:g} s at {args.physics_hz} Hz on "
          f"{topics.key('vehicle/speed')} ...", flush=True)
    try:
        steps = sim.run(stop)
        print(f"# {steps} steps, {sim.bad.count} undecodable commands", flush=True)
    except KeyboardInterrupt:
        stop.set()
    finally:
        session.close()


if __name__ == "__main__":
    main()
