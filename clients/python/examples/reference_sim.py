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
import sys
import time

import _path  # noqa: F401  (source checkout)
import numpy as np

from slipstream_client import cli, connect
from slipstream_client.camera import Pinhole, pinhole_info
from slipstream_client.simulator import RealTimeFactor, SimulatorSide

LANES, LANE_W = 3, 3.5
CAR_SIZE, CAR_REAR_OVERHANG = [4.6, 1.85, 1.45], 0.95
# Forward dynamics of the default car (the inverse is config/acc.json5's vehicle model).
MASS_KG, MAX_FORCE_N, MAX_POWER_W, MAX_BRAKE_MPS2 = 1500.0, 6500.0, 110000.0, 9.0
DRAG_AREA_M2, ROLLING, AIR_DENSITY, G = 0.65, 0.012, 1.2, 9.81
ACTUATOR_LAG_S = 0.3  # throttle and brake follow a command through a first-order lag
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
    """A pinhole camera on the ego: 60 degrees wide, 1.35 m up, pitched 3 degrees down. The
    scene is drawn for the detector: a daylight road, each vehicle's rear with the dark band
    where it meets the road."""

    def __init__(self, width, height, rate_hz, fov_deg=60.0, mount=(1.6, 0.0, 1.35), pitch_deg=3.0):
        self.info = pinhole_info(width, height, fov_deg, mount, pitch_deg, rate_hz)
        self.pin = Pinhole(self.info)
        self.w, self.h, self.rate_hz = width, height, rate_hz
        # Where each pixel's ray meets the ground (ego frame), once: the road is straight and
        # the ego keeps its lane, so only the dashes move.
        u, v = np.meshgrid(np.arange(width) + 0.5, np.arange(height) + 0.5)
        cp, sp = math.cos(self.pin.pitch), math.sin(self.pin.pitch)
        right, up = (u - self.pin.cx) / self.pin.fx, (self.pin.cy - v) / self.pin.fy
        dx, dz = cp + up * sp, -sp + up * cp
        ground = dz < -1e-6
        t = np.where(ground, -mount[2] / np.where(ground, dz, -1.0), 0.0)
        self.gx, self.gy = mount[0] + t * dx, mount[1] - t * right
        road = ground & (np.abs(self.gy) <= LANES * LANE_W / 2) & (self.gx < 400)
        self.base = np.empty((height, width, 3), np.uint8)
        self.base[:] = SKY
        self.base[ground] = GRASS
        self.base[road] = ASPHALT
        lines = [lane_d(i) + LANE_W / 2 for i in range(LANES - 1)]
        self.marking = road & (np.min([np.abs(self.gy - y) for y in lines], axis=0) < 0.075) & (self.gx < 160)

    def render(self, ego_s, others):
        """The frame (H x W x 3 RGB8) and each vehicle's (bbox, visible fraction)."""
        img = self.base.copy()
        img[self.marking & (((self.gx + ego_s) % 12.0) < 3.0)] = MARKING
        boxes = {}
        for o in sorted(others, key=lambda o: -o["x"]):  # far to near
            boxes[o["id"]] = self.draw(img, o)
        return img, boxes

    def draw(self, img, o):
        box, visible = self.pin.rear_box(o["x"], o["y"], CAR_SIZE[1], CAR_SIZE[2])
        if box is None:
            return None, 0.0
        (u0, v0), (u1, v1) = (self.pin.project(o["x"], o["y"] + CAR_SIZE[1] / 2, CAR_SIZE[2]),
                              self.pin.project(o["x"], o["y"] - CAR_SIZE[1] / 2, 0.0))
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
        return box, visible


class ReferenceSim:
    """The world (ego, traffic, camera) stepped and published through a SimulatorSide."""

    def __init__(self, side, args):
        self.side, self.args = side, args
        self.camera = Camera(*args.camera_size, args.camera_hz)
        self.ego = Vehicle(0, 1, 0.0, 25.0, None)
        self.traffic = [Vehicle(1, 1, 45.0, 22.0, (150, 32, 36), [(12, 12.0, 3.0), (25, 22.0, 1.0)]),
                        Vehicle(2, 2, 75.0, 26.0, (40, 70, 160))]
        # Throttle and brake as the actuators have them; at the start, what holds 25 m/s.
        self.pedals = [resistance(25.0) / min(MAX_FORCE_N, MAX_POWER_W / 25.0), 0.0]

    def state(self):
        ego = self.ego
        return {"position_in_world_m": [ego.s, lane_d(ego.lane), 0.0], "yaw_in_world_rad": 0.0, "pitch_rad": 0.0,
                "roll_rad": 0.0, "velocity_in_world_mps": [ego.v, 0.0, 0.0],
                "acceleration_in_body_mps2": [ego.a, 0.0, 0.0], "yaw_rate_radps": 0.0, "speed_mps": ego.v,
                "lane": ego.lane}

    def publish_frame(self, k):
        ego, front = self.ego, CAR_SIZE[0] - CAR_REAR_OVERHANG
        others = [{"id": v.id, "x": v.s - CAR_REAR_OVERHANG - ego.s, "y": lane_d(v.lane) - lane_d(ego.lane),
                   "color": v.color, "braking": v.braking} for v in self.traffic]
        img, boxes = self.camera.render(ego.s, [o for o in others if o["x"] > front])
        frame = {"width": self.camera.w, "height": self.camera.h, "encoding": "Rgb8", "data": img.tobytes()}
        objects = []
        for v, o in zip(self.traffic, others):
            bbox, visible = boxes.get(v.id, (None, 0.0))
            objects.append({
                "id": v.id, "class": "Car", "size_m": CAR_SIZE, "lane": v.lane,
                "position_in_world_m": [v.s, lane_d(v.lane), 0.0], "yaw_in_world_rad": 0.0,
                "velocity_in_world_mps": [v.v, 0.0, 0.0], "position_in_ego_m": [o["x"], o["y"], CAR_SIZE[2] / 2],
                "yaw_in_ego_rad": 0.0, "velocity_in_ego_mps": [v.v - ego.v, 0.0, 0.0], "bbox": bbox,
                "visible_fraction": visible, "brake_lights": v.braking})
        self.side.publish_frame(k, frame, objects)

    def physics(self, k, dt, cmd):
        ego = self.ego
        if cmd is None:
            ego.a = 0.0  # before the first command: hold the start speed
        else:
            lag = min(1.0, dt / ACTUATOR_LAG_S)
            self.pedals = [p + (c - p) * lag for p, c in zip(self.pedals, (cmd["throttle"], cmd["brake"]))]
            throttle, brake = self.pedals
            drive = throttle * min(MAX_FORCE_N, MAX_POWER_W / max(ego.v, 1.0))
            ego.a = (drive - resistance(ego.v)) / MASS_KG - brake * MAX_BRAKE_MPS2
        ego.v = max(0.0, ego.v + ego.a * dt)
        ego.s += ego.v * dt
        for v in self.traffic:
            v.drive(k * dt, dt)
            gap = v.s - CAR_REAR_OVERHANG - (ego.s + CAR_SIZE[0] - CAR_REAR_OVERHANG)
            if v.lane == ego.lane and gap < 0 and not getattr(v, "hit", False):
                v.hit = True
                self.side.event(k + 1, "Collision", other_id=v.id, relative_speed_mps=ego.v - v.v)

    def run(self, stop):
        side, hz = self.side, self.side.hz
        road = {"lanes": LANES, "lane_width_m": LANE_W, "length_m": 5000.0, "curves": [], "lane_ends": []}
        side.start(self.camera.info, road, scenario="reference")
        dt, steps, rtf = 1.0 / hz, round(self.args.duration * hz), RealTimeFactor()
        started, k = time.monotonic(), 0
        for k in range(steps + 1):
            if stop.is_set():
                break
            side.publish_ego(k, self.ego.v, self.state(), rtf(k * dt))
            if k % round(hz / self.camera.rate_hz) == 0:
                self.publish_frame(k)
            if k == steps:
                break
            self.physics(k, dt, side.control(k))
            if side.mode == "realtime":
                time.sleep(max(0.0, started + (k + 1) * dt - time.monotonic()))
        side.end(k, "stopped" if stop.is_set() else "duration reached")
        return k


def resistance(speed):
    """Rolling resistance and drag, N."""
    return ROLLING * MASS_KG * G + 0.5 * AIR_DENSITY * DRAG_AREA_M2 * speed * speed


def size(text):
    w, _, h = text.partition("x")
    return int(w), int(h)


def parser():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--physics-hz", type=int, default=100, help="steps per simulated second [default: 100]")
    p.add_argument("--camera-size", type=size, default=(640, 480), help="WIDTHxHEIGHT [default: 640x480]")
    cli.add_clock_args(p, "realtime", 60.0)
    connect.add_args(p)
    return p


def main(sim_class=ReferenceSim, side_class=SimulatorSide):
    args = parser().parse_args()
    if args.physics_hz % args.camera_hz or not 0 < args.camera_hz <= args.physics_hz:
        raise SystemExit("--camera-hz must divide --physics-hz")
    session, topics = cli.open_session(args)
    side = side_class(session, topics, args.mode, args.physics_hz, args.wait_for or ["acc"], args.step_timeout)
    print(f"# reference simulator: {args.mode}, {args.duration:g} s at {args.physics_hz} Hz on "
          f"{topics.key('vehicle/speed')} ...", flush=True)
    return cli.run_world(side, session, lambda side: sim_class(side, args))

if __name__ == "__main__":
    sys.exit(main())
