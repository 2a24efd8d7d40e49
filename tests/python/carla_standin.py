"""A stand-in for a CARLA server: the part of CARLA's client API the adapter calls
(clients/python/adapters/carla_adapter.py), answered by a small world instead of Unreal, and
built on the `carla` package's own value types (Transform, Location, Rotation, Vector3D,
BoundingBox, VehicleControl, WorldSettings, LaneType). Nothing here talks to a server.

The world: a straight three-lane road along CARLA's x axis (lanes at y = -3.5, 0, 3.5: CARLA's
y points right), the ego (role_name hero) in the middle lane at 25 m/s, a car 45 m ahead at
22 m/s that slows to 12 m/s at 12 s, a faster car in the left lane. Synchronous mode steps on
`tick()`; asynchronous mode steps on a thread at the wall clock. The RGB camera draws with the
reference simulator's renderer and calls back from a thread of its own, as CARLA's sensor
thread does, BGRA as CARLA sends it.

    python tests/python/carla_standin.py [carla_adapter flags]   # the adapter on the stand-in

STANDIN_DIE_AFTER=S: the server stops answering after S simulated seconds (tick raises CARLA's
time-out RuntimeError)."""

import fnmatch
import os
import pathlib
import sys
import threading
import time

import carla
import numpy as np

ROOT = pathlib.Path(__file__).resolve().parents[2]
sys.path[:0] = [str(ROOT / "clients" / "python" / "examples"), str(ROOT / "clients" / "python" / "adapters")]
import carla_adapter  # noqa: E402
from reference_sim import CAR_REAR_OVERHANG, Camera  # noqa: E402

EXTENT = carla.Vector3D(2.3, 0.925, 0.725)
LANE_Y = {0: 3.5, 1: 0.0, 2: -3.5}  # CARLA y of each lane's centre (lane 0: the rightmost)


class Waypoint:
    def __init__(self, lane):
        self.lane, self.lane_id, self.lane_type = lane, -(3 - lane), carla.LaneType.Driving

    def get_right_lane(self):
        return Waypoint(self.lane - 1) if self.lane > 0 else None


class Map:
    name = "Standin/Straight3"

    def get_spawn_points(self):
        return [carla.Transform(carla.Location(x=0.0, y=LANE_Y[1], z=0.0), carla.Rotation(yaw=0.0))]

    def get_waypoint(self, location, project_to_road=True):
        lane = min(LANE_Y, key=lambda i: abs(LANE_Y[i] - location.y))
        return Waypoint(lane) if abs(LANE_Y[lane] - location.y) < 1.75 else None


class Vehicle:
    def __init__(self, world, vid, x, lane, speed, role="autopilot", profile=()):
        self.world, self.id, self.type_id = world, vid, "vehicle.standin.car"
        self.attributes = {"role_name": role, "number_of_wheels": "4"}
        self.bounding_box = carla.BoundingBox(carla.Location(0.0, 0.0, EXTENT.z), EXTENT)
        self.x, self.y, self.v, self.a, self.profile = x, LANE_Y[lane], speed, 0.0, list(profile)
        self.control, self.pedals = carla.VehicleControl(), [0.2, 0.0]

    def get_transform(self):
        return carla.Transform(carla.Location(x=self.x, y=self.y, z=0.0), carla.Rotation(yaw=0.0))

    def get_location(self):
        return carla.Location(x=self.x, y=self.y, z=0.0)

    def get_velocity(self):
        return carla.Vector3D(self.v, 0.0, 0.0)

    def get_angular_velocity(self):
        return carla.Vector3D(0.0, 0.0, 0.0)

    def get_control(self):
        return self.control

    def apply_control(self, control):
        self.control = control

    def step(self, t, dt):
        if self.attributes["role_name"] == "hero":  # point mass, the pedals through a 0.3 s lag
            lag = min(1.0, dt / 0.3)
            self.pedals = [p + (c - p) * lag for p, c in zip(self.pedals, (self.control.throttle, self.control.brake))]
            drive = self.pedals[0] * min(6500.0, 110000.0 / max(self.v, 1.0))
            self.a = (drive - 176.6 - 0.39 * self.v * self.v) / 1500.0 - self.pedals[1] * 9.0
        else:
            target, rate = self.v, 0.0
            for start, speed, accel in self.profile:
                if t >= start:
                    target, rate = speed, accel
            self.a = max(-rate, min(rate, (target - self.v) / dt)) if rate else 0.0
            self.control = carla.VehicleControl(throttle=0.0, brake=0.5 if self.a < -0.5 else 0.0)
        self.v = max(0.0, self.v + self.a * dt)
        self.x += self.v * dt


class RgbCamera:
    """sensor.camera.rgb: draws the scene every sensor_tick and calls back on its own thread."""

    def __init__(self, world, attributes, transform, parent):
        self.world, self.parent, self.id, self.type_id = world, parent, 100, "sensor.camera.rgb"
        w, h = int(attributes["image_size_x"]), int(attributes["image_size_y"])
        mount_x = transform.location.x - (parent.bounding_box.location.x - EXTENT.x + CAR_REAR_OVERHANG)
        tick = float(attributes.get("sensor_tick", "0"))  # 0: every tick, as CARLA does
        self.renderer = Camera(w, h, 1.0 / tick if tick > 0 else 20.0, float(attributes["fov"]),
                               (mount_x, 0.0, transform.location.z), -transform.rotation.pitch)
        self.tick_s, self.next_s, self.callback, self.pending = tick, 0.0, None, []
        self.ready = threading.Condition()
        threading.Thread(target=self.deliver, daemon=True).start()

    def listen(self, callback):
        self.callback = callback

    def stop(self):
        self.callback = None

    def destroy(self):
        self.stop()

    def capture(self, frame, elapsed):
        if self.callback is None or elapsed + 1e-9 < self.next_s:
            return
        self.next_s += self.tick_s
        ego = self.parent
        rear_axle = ego.x - EXTENT.x + CAR_REAR_OVERHANG
        others = [{"id": v.id, "x": v.x - EXTENT.x - rear_axle, "y": -(v.y - ego.y), "color": (150, 32, 36),
                   "braking": v.control.brake > 0.1} for v in self.world.vehicles if v is not ego]
        rgb, _ = self.renderer.render(rear_axle, [o for o in others if o["x"] > 4.0])
        bgra = np.concatenate([rgb[:, :, ::-1], np.full(rgb.shape[:2] + (1,), 255, np.uint8)], axis=2)
        image = type("Image", (), {"raw_data": bgra.tobytes(), "width": rgb.shape[1], "height": rgb.shape[0],
                                   "frame": frame, "timestamp": elapsed})()
        with self.ready:
            self.pending.append(image)
            self.ready.notify()

    def deliver(self):
        while True:
            with self.ready:
                while not self.pending:
                    self.ready.wait()
                image = self.pending.pop(0)
            if self.callback is not None:
                self.callback(image)


class Library:
    class Blueprint:
        def __init__(self, bp_id):
            self.id, self.attributes = bp_id, {}

        def set_attribute(self, key, value):
            self.attributes[key] = value

    def find(self, bp_id):
        return Library.Blueprint(bp_id)


class ActorList(list):
    def filter(self, pattern):
        return ActorList(a for a in self if fnmatch.fnmatch(a.type_id, pattern))


class World:
    def __init__(self):
        self.settings, self.frame, self.elapsed, self.map = carla.WorldSettings(), 0, 0.0, Map()
        self.vehicles = [Vehicle(self, 2, 45.0 + 2 * EXTENT.x, 1, 22.0, profile=[(12, 12.0, 3.0), (25, 22.0, 1.0)]),
                         Vehicle(self, 3, 75.0 + 2 * EXTENT.x, 2, 26.0)]
        self.sensors, self.lock, self.ticked = [], threading.RLock(), threading.Condition()
        self.die_after = float(os.environ.get("STANDIN_DIE_AFTER", "inf"))
        threading.Thread(target=self.free_run, daemon=True).start()

    def get_settings(self):
        s = carla.WorldSettings()
        s.synchronous_mode, s.fixed_delta_seconds = self.settings.synchronous_mode, self.settings.fixed_delta_seconds
        return s

    def apply_settings(self, settings):
        self.settings = settings
        return self.frame

    def get_map(self):
        return self.map

    def get_blueprint_library(self):
        return Library()

    def get_actors(self):
        return ActorList(self.vehicles)

    def spawn_actor(self, bp, transform, attach_to=None):
        if bp.id == "sensor.camera.rgb":
            camera = RgbCamera(self, bp.attributes, transform, attach_to)
            self.sensors.append(camera)
            return camera
        ego = Vehicle(self, 1, transform.location.x, 1, 25.0, role=bp.attributes.get("role_name", "autopilot"))
        self.vehicles.append(ego)
        return ego

    def step(self, dt):
        with self.lock:
            if self.elapsed >= self.die_after:
                raise RuntimeError("time-out of 10000ms while waiting for the simulator, make sure the simulator "
                                   "is ready and connected to 127.0.0.1:2000")
            for v in self.vehicles:
                v.step(self.elapsed, dt)
            self.frame, self.elapsed = self.frame + 1, self.elapsed + dt
            for s in self.sensors:
                s.capture(self.frame, self.elapsed)
        with self.ticked:
            self.ticked.notify_all()
        return self.frame

    def tick(self, seconds=10.0):
        if not self.settings.synchronous_mode:
            raise RuntimeError("tick() in asynchronous mode")
        return self.step(self.settings.fixed_delta_seconds or 0.05)

    def free_run(self):
        """Asynchronous mode: the server steps at its own pace (here 100 frames a wall second)."""
        while True:
            time.sleep(0.01)
            if not self.settings.synchronous_mode and self.elapsed < self.die_after:
                self.step(0.01)

    def wait_for_tick(self, seconds=10.0):
        with self.ticked:
            if not self.ticked.wait(seconds):
                raise RuntimeError(f"time-out of {seconds * 1000:.0f}ms while waiting for the simulator")
        timestamp = type("Timestamp", (), {"elapsed_seconds": self.elapsed, "delta_seconds": 0.01, "frame": self.frame})
        return type("WorldSnapshot", (), {"frame": self.frame, "timestamp": timestamp})()


class Client:
    """carla.Client's constructor, set_timeout and get_world."""

    def __init__(self, host, port):
        if host != "127.0.0.1":
            raise RuntimeError(f"time-out of 2000ms while waiting for the simulator at {host}:{port}")
        self.world = World()

    def set_timeout(self, seconds):
        self.timeout = seconds

    def get_world(self):
        return self.world


if __name__ == "__main__":
    sys.exit(carla_adapter.main(client_class=Client))
