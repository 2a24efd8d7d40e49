"""A stand-in for a CARLA server: the part of CARLA's client API the adapter calls
(clients/python/adapters/carla_adapter.py), answered by a small world instead of Unreal, and
built on the `carla` package's own value types (Transform, Location, Rotation, Vector3D,
BoundingBox, VehicleControl, WorldSettings, LaneType). Nothing here talks to a server.

The world is standin_world's road along CARLA's x axis (CARLA's y points right, so y and yaw
are mirrored here). Synchronous mode steps on `tick()`; asynchronous mode steps on a thread at
the wall clock. The RGB camera calls back from a thread of its own, as CARLA's sensor thread
does, BGRA as CARLA sends it.

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
sys.path.insert(0, str(ROOT / "clients" / "python" / "adapters"))
import carla_adapter  # noqa: E402
from standin_world import CAR_REAR_OVERHANG, CAR_SIZE, HALF_LENGTH, camera, draw, lane_d, road_world  # noqa: E402

EXTENT = carla.Vector3D(HALF_LENGTH, CAR_SIZE[1] / 2, CAR_SIZE[2] / 2)


def carla_y(lane):
    return -lane_d(lane)  # CARLA's y points right


class Waypoint:
    def __init__(self, lane):
        self.lane, self.lane_id, self.lane_type = lane, -(3 - lane), carla.LaneType.Driving

    def get_right_lane(self):
        return Waypoint(self.lane - 1) if self.lane > 0 else None


class Map:
    name = "Standin/Straight3"

    def get_spawn_points(self):
        return [carla.Transform(carla.Location(x=0.0, y=carla_y(1), z=0.0), carla.Rotation(yaw=0.0))]

    def get_waypoint(self, location, project_to_road=True):
        lane = min(range(3), key=lambda i: abs(carla_y(i) - location.y))
        return Waypoint(lane) if abs(carla_y(lane) - location.y) < 1.75 else None


class Vehicle:
    """A carla.Vehicle's getters over a standin_world.Mover (y and yaw mirrored)."""

    def __init__(self, mover, role="autopilot"):
        self.m, self.id, self.type_id = mover, mover.id, "vehicle.standin.car"
        self.attributes = {"role_name": role, "number_of_wheels": "4"}
        self.bounding_box = carla.BoundingBox(carla.Location(0.0, 0.0, EXTENT.z), EXTENT)
        self.control = carla.VehicleControl()

    def get_transform(self):
        return carla.Transform(carla.Location(x=self.m.x, y=-self.m.y, z=0.0), carla.Rotation(yaw=0.0))

    def get_location(self):
        return carla.Location(x=self.m.x, y=-self.m.y, z=0.0)

    def get_velocity(self):
        return carla.Vector3D(self.m.v, 0.0, 0.0)

    def get_angular_velocity(self):
        return carla.Vector3D(0.0, 0.0, 0.0)

    def get_control(self):
        if not self.m.hero:
            return carla.VehicleControl(throttle=0.0, brake=0.5 if self.m.braking else 0.0)
        return self.control

    def apply_control(self, control):
        self.control = control
        self.m.command = (control.throttle, control.brake)


class RgbCamera:
    """sensor.camera.rgb: draws the scene every sensor_tick (0: every tick) and calls back on a
    thread of its own, BGRA rows top to bottom."""

    def __init__(self, world, attributes, transform, parent):
        self.world, self.id, self.type_id = world, 100, "sensor.camera.rgb"
        w, h = int(attributes["image_size_x"]), int(attributes["image_size_y"])
        mount_x = transform.location.x - (parent.bounding_box.location.x - EXTENT.x + CAR_REAR_OVERHANG)
        self.camera = camera(w, h, float(attributes["fov"]), (mount_x, 0.0, transform.location.z),
                             -transform.rotation.pitch)
        self.tick_s, self.next_s = float(attributes.get("sensor_tick", "0")), 0.0
        self.callback, self.pending, self.ready = None, [], threading.Condition()
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
        rgb = draw(self.camera, self.world.movers)
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
        self.movers = road_world()
        self.vehicles = [Vehicle(m) for m in self.movers if not m.hero]
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
        hero = next(m for m in self.movers if m.hero)
        hero.x = transform.location.x
        ego = Vehicle(hero, role=bp.attributes.get("role_name", "autopilot"))
        self.vehicles.append(ego)
        return ego

    def step(self, dt):
        with self.lock:
            if self.elapsed >= self.die_after:
                raise RuntimeError("time-out of 10000ms while waiting for the simulator, make sure the simulator "
                                   "is ready and connected to 127.0.0.1:2000")
            for m in self.movers:
                m.step(self.elapsed, dt)
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
