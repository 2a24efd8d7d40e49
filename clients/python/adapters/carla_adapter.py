#!/usr/bin/env python3
"""CARLA on slipstream's bus: the simulator side of docs/simulator-contract.md for a CARLA
server, so slipstream-detect, slipstream-acc and the tools run around CARLA as they run around
slipstream-sim.

    python3 clients/python/adapters/carla_adapter.py --host CARLA-PC --mode lockstep &
    slipstream conform sim --lockstep                  # check it, then:
    slipstream up --sim external --mode lockstep

It attaches to the vehicle whose role_name is `hero` (or spawns one), attaches an RGB camera
(size and field of view from the flags, mounted where camera/front/info says), and publishes
vehicle/speed, vehicle/state and sim/clock every step, camera/front and objects (every other
vehicle, with its rear face's box projected into the camera) at --camera-hz, camera/front/info
latched; vehicle/control becomes carla.VehicleControl.

Clock modes: lockstep runs CARLA in synchronous mode and ticks once the loop has answered the
step; fast ticks synchronously as fast as CARLA renders; realtime leaves CARLA asynchronous (its
own pace) and publishes each frame it reports, on the step grid of --physics-hz. Camera images
come on CARLA's sensor thread and only go into a queue there: publishing happens in the
adapter's loop, never in CARLA's callback.

Frames: CARLA is left-handed (x forward, y right, yaw clockwise in degrees); slipstream's are
right-handed (y left, yaw counter-clockwise in radians): y and yaw change sign. The body origin
is the rear axle on the ground: taken as the bounding box's rear face moved forward by
--rear-overhang (CARLA reports no axle)."""

import argparse
import math
import queue
import sys
import time

import carla
import numpy as np

try:
    from slipstream_client import cli, connect
except ImportError:  # a source checkout
    sys.path.insert(0, str(__import__("pathlib").Path(__file__).resolve().parents[1]))
    from slipstream_client import cli, connect
from slipstream_client.camera import Pinhole, pinhole_info
from slipstream_client.simulator import RealTimeFactor, SimulatorSide


class Body:
    """An actor in slipstream's frames: rear-axle origin on the ground, y left, yaw CCW."""

    def __init__(self, actor, rear_overhang):
        t, box = actor.get_transform(), actor.bounding_box
        self.yaw = -math.radians(t.rotation.yaw)
        fwd = (math.cos(self.yaw), math.sin(self.yaw))
        # Transform.transform rewrites the point it is given: hand it a copy.
        centre = t.transform(carla.Location(box.location.x, box.location.y, box.location.z))
        cx, cy = centre.x, -centre.y
        back = box.extent.x - rear_overhang
        self.x, self.y = cx - fwd[0] * back, cy - fwd[1] * back
        self.rear = (cx - fwd[0] * box.extent.x, cy - fwd[1] * box.extent.x)
        self.size = [2 * box.extent.x, 2 * box.extent.y, 2 * box.extent.z]
        v = actor.get_velocity()
        self.v = (v.x, -v.y, v.z)
        self.yaw_rate = -math.radians(actor.get_angular_velocity().z)
        self.pitch, self.roll = -math.radians(t.rotation.pitch), math.radians(t.rotation.roll)

    def to_body(self, x, y):
        """A world point (slipstream's world frame) in this body's frame."""
        dx, dy, c, s = x - self.x, y - self.y, math.cos(self.yaw), math.sin(self.yaw)
        return c * dx + s * dy, -s * dx + c * dy

    def rotate(self, vx, vy):
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        return c * vx + s * vy, -s * vx + c * vy


def lane_of(world_map, actor):
    """Driving lanes to the right of the actor's lane (0: the rightmost), -1 off the road."""
    wp = world_map.get_waypoint(actor.get_location(), project_to_road=False)
    if wp is None:
        return -1
    n, right = 0, wp.get_right_lane()
    while right is not None and right.lane_type == carla.LaneType.Driving and n < 16:
        n, right = n + 1, right.get_right_lane()
    return n


def object_class(actor, size):
    if actor.attributes.get("number_of_wheels") == "2":
        return "Motorcycle"
    return "Truck" if size[0] > 7 else "Van" if size[0] > 5.2 or size[2] > 2.1 else "Car"


class CarlaAdapter:
    """The CARLA world, stepped (or followed) and published through a SimulatorSide."""

    def __init__(self, side, world, args):
        self.side, self.world, self.args = side, world, args
        self.map = world.get_map()
        self.ego = self.find_or_spawn_ego()
        self.info = pinhole_info(*args.camera_size, args.fov, (args.mount_x, 0.0, args.mount_z), args.pitch,
                                 args.camera_hz)
        self.pin = Pinhole(self.info)
        self.images = queue.Queue(maxsize=8)
        self.camera = self.spawn_camera()
        self.previous_v = None

    def find_or_spawn_ego(self):
        for actor in self.world.get_actors().filter("vehicle.*"):
            if actor.attributes.get("role_name") == self.args.role_name:
                return actor
        bp = self.world.get_blueprint_library().find(self.args.blueprint)
        bp.set_attribute("role_name", self.args.role_name)
        spawn = self.map.get_spawn_points()[self.args.spawn_point]
        return self.world.spawn_actor(bp, spawn)

    def spawn_camera(self):
        bp = self.world.get_blueprint_library().find("sensor.camera.rgb")
        w, h = self.args.camera_size
        # Stepped (lockstep, fast): an image every tick, the adapter keeps the camera steps' (a
        # sensor_tick would land on whichever tick its clock reaches, not on the steps the
        # contract and a lockstep ACC expect). Free-running (realtime): CARLA's own tick.
        tick = 1.0 / self.args.camera_hz if self.args.mode == "realtime" else 0.0
        for key, value in (("image_size_x", w), ("image_size_y", h), ("fov", self.args.fov), ("sensor_tick", tick)):
            bp.set_attribute(key, str(value))
        box = self.ego.bounding_box
        # Mount in the body frame -> relative to the actor's origin (CARLA: y right, pitch up).
        x = box.location.x - box.extent.x + self.args.rear_overhang + self.args.mount_x
        mount = carla.Transform(carla.Location(x=x, y=0.0, z=self.args.mount_z), carla.Rotation(pitch=-self.args.pitch))
        camera = self.world.spawn_actor(bp, mount, attach_to=self.ego)
        camera.listen(self.on_image)
        return camera

    def on_image(self, image):
        """CARLA's sensor thread: keep the newest few, never block, never publish here."""
        try:
            self.images.put_nowait(image)
        except queue.Full:
            self.images.get_nowait()
            self.images.put_nowait(image)

    def state(self, dt):
        ego = Body(self.ego, self.args.rear_overhang)
        vx, vy = ego.rotate(ego.v[0], ego.v[1])
        accel = 0.0 if self.previous_v is None or dt <= 0 else (vx - self.previous_v) / dt
        self.previous_v = vx
        speed = math.sqrt(sum(c * c for c in ego.v))
        return ego, speed, {
            "position_in_world_m": [ego.x, ego.y, 0.0], "yaw_in_world_rad": ego.yaw, "pitch_rad": ego.pitch,
            "roll_rad": ego.roll, "velocity_in_world_mps": list(ego.v), "acceleration_in_body_mps2": [accel, 0.0, 0.0],
            "yaw_rate_radps": ego.yaw_rate, "speed_mps": speed, "lane": lane_of(self.map, self.ego)}

    def objects(self, ego):
        out = []
        for actor in self.world.get_actors().filter("vehicle.*"):
            if actor.id == self.ego.id:
                continue
            o = Body(actor, self.args.rear_overhang)
            x, y = ego.to_body(*o.rear)
            vx, vy = ego.rotate(o.v[0] - ego.v[0], o.v[1] - ego.v[1])
            vx, vy = vx + ego.yaw_rate * y, vy - ego.yaw_rate * x
            box, visible = self.pin.rear_box(x, y, o.size[1], o.size[2]) if x > 0 else (None, 0.0)
            control = actor.get_control() if hasattr(actor, "get_control") else None
            out.append({
                "id": actor.id, "class": object_class(actor, o.size), "size_m": o.size, "lane": lane_of(self.map, actor),
                "position_in_world_m": [o.x, o.y, 0.0], "yaw_in_world_rad": o.yaw, "velocity_in_world_mps": list(o.v),
                "position_in_ego_m": [x, y, o.size[2] / 2], "yaw_in_ego_rad": o.yaw - ego.yaw,
                "velocity_in_ego_mps": [vx, vy, 0.0], "bbox": box, "visible_fraction": visible,
                "brake_lights": bool(control is not None and control.brake > 0.1)})
        return out

    def frame_of(self, image):
        """A CameraFrame body from a CARLA image (BGRA rows top to bottom)."""
        bgra = np.frombuffer(image.raw_data, np.uint8).reshape(image.height, image.width, 4)
        return {"width": image.width, "height": image.height, "encoding": "Rgb8",
                "data": np.ascontiguousarray(bgra[:, :, 2::-1]).tobytes()}

    def apply(self, cmd):
        if cmd is not None:
            self.ego.apply_control(carla.VehicleControl(throttle=cmd["throttle"], brake=cmd["brake"],
                                                        steer=-cmd["steer"]))

    def publish(self, k, frame_id, dt, rtf, ego_cache):
        ego, speed, state = self.state(dt)
        ego_cache[frame_id] = (k, ego)
        for old in [f for f in ego_cache if f < frame_id - 64]:  # images older than this are gone
            del ego_cache[old]
        self.side.publish_ego(k, speed, state, rtf)
        return ego

    def publish_images(self, seen):
        """Realtime: images of frames already published, with that frame's step and ground truth."""
        while True:
            try:
                image = self.images.get_nowait()
            except queue.Empty:
                return
            if image.frame in seen:
                k, ego = seen[image.frame]
                self.side.publish_frame(k, self.frame_of(image), self.objects(ego))
            elif image.frame > max(seen, default=-1):
                self.on_image(image)  # its step is not out yet
                return

    def image_of(self, frame_id, timeout):
        """Synchronous mode: the image of tick `frame_id` (it comes just after the tick), older
        ones dropped; None when it does not come within `timeout` seconds."""
        deadline = time.monotonic() + timeout
        while True:
            try:
                image = self.images.get(timeout=max(0.0, deadline - time.monotonic()))
            except queue.Empty:
                return None
            if image.frame == frame_id:
                return image
            if image.frame > frame_id:
                return None

    def run(self, stop):
        """Steps until --duration simulated seconds or a stop; returns the steps taken."""
        side, hz, dt = self.side, self.side.hz, 1.0 / self.side.hz
        settings = self.world.get_settings()
        settings.synchronous_mode = side.mode != "realtime"
        settings.fixed_delta_seconds = dt if side.mode != "realtime" else None
        self.world.apply_settings(settings)
        side.start(self.info, None, scenario=f"carla:{self.map.name}")
        steps, rtf, seen, k = round(self.args.duration * hz), RealTimeFactor(), {}, 0
        every = round(hz / self.args.camera_hz)
        if side.mode == "realtime":
            t0 = self.world.wait_for_tick(self.args.timeout).timestamp.elapsed_seconds
            while k < steps and not stop.is_set():
                snap = self.world.wait_for_tick(self.args.timeout)
                now = round((snap.timestamp.elapsed_seconds - t0) * hz)
                if now <= k and seen:
                    continue
                k = now
                self.publish(k, snap.frame, snap.timestamp.delta_seconds, rtf(k * dt), seen)
                self.publish_images(seen)
                self.apply(side.control(k))
        else:
            frame_id = self.world.tick(self.args.timeout)
            while k <= steps and not stop.is_set():
                ego = self.publish(k, frame_id, dt, rtf(k * dt), seen)
                image = self.image_of(frame_id, self.args.timeout) if k % every == 0 else None
                if image is not None:
                    side.publish_frame(k, self.frame_of(image), self.objects(ego))
                if k == steps:
                    break
                self.apply(side.control(k))
                frame_id, k = self.world.tick(self.args.timeout), k + 1
        side.end(k, "stopped" if stop.is_set() else "duration reached")
        return k

    def close(self):
        self.camera.stop()
        self.camera.destroy()
        settings = self.world.get_settings()
        settings.synchronous_mode, settings.fixed_delta_seconds = False, None
        self.world.apply_settings(settings)


def size(text):
    w, _, h = text.partition("x")
    return int(w), int(h)


def parser():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--host", default="127.0.0.1", help="CARLA server [default: 127.0.0.1]")
    p.add_argument("--port", type=int, default=2000, help="CARLA server port [default: 2000]")
    p.add_argument("--timeout", type=float, default=10.0, help="seconds CARLA may take to answer [default: 10]")
    p.add_argument("--physics-hz", type=int, default=100, help="steps per simulated second [default: 100]")
    p.add_argument("--camera-size", type=size, default=(640, 480), help="WIDTHxHEIGHT [default: 640x480]")
    p.add_argument("--fov", type=float, default=60.0, help="horizontal field of view, degrees [default: 60]")
    p.add_argument("--mount-x", type=float, default=1.6, help="camera ahead of the rear axle, m [default: 1.6]")
    p.add_argument("--mount-z", type=float, default=1.35, help="camera above the ground, m [default: 1.35]")
    p.add_argument("--pitch", type=float, default=3.0, help="camera pitch down, degrees [default: 3]")
    p.add_argument("--rear-overhang", type=float, default=0.95, help="rear bumper to rear axle, m [default: 0.95]")
    p.add_argument("--role-name", default="hero", help="the ego's role_name attribute [default: hero]")
    p.add_argument("--blueprint", default="vehicle.tesla.model3", help="spawned when no ego is found")
    p.add_argument("--spawn-point", type=int, default=0, help="index into the map's spawn points [default: 0]")
    cli.add_clock_args(p, "lockstep", 3600.0)
    connect.add_args(p)
    return p


def main(client_class=None):
    """Runs the adapter; exits 1 when CARLA cannot be reached or stops answering."""
    args = parser().parse_args()
    if args.physics_hz % args.camera_hz:
        raise SystemExit("--camera-hz must divide --physics-hz")
    try:
        client = (client_class or carla.Client)(args.host, args.port)
        client.set_timeout(args.timeout)
        world = client.get_world()
    except RuntimeError as e:
        raise SystemExit(f"carla adapter: cannot reach CARLA at {args.host}:{args.port}: {e}") from None
    session, topics = cli.open_session(args)
    side = SimulatorSide(session, topics, args.mode, args.physics_hz, args.wait_for or ["acc"], args.step_timeout)

    def make(side):
        adapter = CarlaAdapter(side, world, args)
        print(f"# carla adapter: {args.mode} at {args.physics_hz} Hz, ego {adapter.ego.type_id} #{adapter.ego.id}, "
              f"on {topics.key('vehicle/speed')}", flush=True)
        return adapter

    # CARLA's client raises RuntimeError on a lost server (its time-out).
    return cli.run_world(side, session, make, {RuntimeError: lambda e: f"carla adapter: lost the CARLA server: {e}"})

if __name__ == "__main__":
    sys.exit(main())
