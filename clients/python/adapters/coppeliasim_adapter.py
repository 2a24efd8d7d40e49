#!/usr/bin/env python3
"""CoppeliaSim on slipstream's bus: the simulator side of docs/simulator-contract.md for a
CoppeliaSim scene, through CoppeliaSim's ZMQ remote API (`coppeliasim-zmqremoteapi-client`).

    python3 clients/python/adapters/coppeliasim_adapter.py --ego /Car --camera /Car/visionSensor \\
        --traffic /Lead --mode lockstep &
    slipstream conform sim --lockstep                  # check it, then:
    slipstream up --sim external --mode lockstep

The scene brings a vehicle model (--ego), a vision sensor on it (--camera; its resolution and
perspective angle are read from CoppeliaSim) and, optionally, other vehicles (--traffic). The
adapter publishes vehicle/speed, vehicle/state and sim/clock every simulation step, camera/front
and objects at --camera-hz, camera/front/info latched, and hands each vehicle/control to the
ego's script: `slipstream_control(throttle, brake, steer)` in the script attached to --ego (a
vehicle's actuation is the model's own: README.md has a script for a car with wheel joints).

Clock modes: every mode uses CoppeliaSim's stepping mode (one `sim.step()` per step), so that
the remote calls reading one step (the ego's pose, each vehicle's) all see that step; lockstep
steps once the loop has answered, fast as soon as it can, realtime paced to the wall clock (a
free-running simulation moved on between those calls: the vehicles' positions and the stamp
disagreed by metres under load). The step rate is CoppeliaSim's
time step (Simulation settings): the contract asks for vehicle/speed at >= 50 Hz, so use a
time step of 10 or 20 ms, not the 50 ms default.

Frames: CoppeliaSim's world is right-handed, z up, like slipstream's; a vehicle model's x axis
is taken as its forward direction and its origin as its centre. The rear axle (slipstream's body
origin) is --rear-axle m behind it. Vision sensor images come bottom row first and are flipped."""

import argparse
import math
import sys
import time

import numpy as np
import zmq
from coppeliasim_zmqremoteapi_client import RemoteAPIClient

try:
    from slipstream_client import cli, connect
except ImportError:  # a source checkout
    sys.path.insert(0, str(__import__("pathlib").Path(__file__).resolve().parents[1]))
    from slipstream_client import cli, connect
from slipstream_client.camera import Pinhole
from slipstream_client.simulator import RealTimeFactor, SimulatorSide


class Pose:
    """An object's planar pose and velocity in slipstream's world frame."""

    def __init__(self, sim, handle, back_m):
        x, y, _ = sim.getObjectPosition(handle, sim.handle_world)
        self.yaw = sim.getObjectOrientation(handle, sim.handle_world)[2]
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        self.x, self.y = x - c * back_m, y - s * back_m
        linear, angular = sim.getObjectVelocity(handle)
        self.v, self.yaw_rate = list(linear), angular[2]

    def to_body(self, x, y):
        dx, dy, c, s = x - self.x, y - self.y, math.cos(self.yaw), math.sin(self.yaw)
        return c * dx + s * dy, -s * dx + c * dy


class CoppeliaAdapter:
    def __init__(self, side, sim, args):
        self.side, self.sim, self.args = side, sim, args
        self.ego = sim.getObject(args.ego)
        self.camera = sim.getObject(args.camera)
        self.traffic = [sim.getObject(p) for p in args.traffic]
        self.script = sim.getScript(sim.scripttype_childscript, self.ego)
        _, (w, h) = sim.getVisionSensorImg(self.camera)
        angle = sim.getObjectFloatParam(self.camera, sim.visionfloatparam_perspective_angle)
        # CoppeliaSim's perspective angle spans the larger side of the image.
        fov = angle if w >= h else 2 * math.atan(math.tan(angle / 2) * w / h)
        f = (w / 2) / math.tan(fov / 2)
        self.info = {"width": w, "height": h, "fx_px": f, "fy_px": f, "cx_px": w / 2, "cy_px": h / 2,
                     "horizontal_fov_rad": fov, "mount_position_in_ego_m": self.mount(),
                     "mount_roll_pitch_yaw_rad": [0.0, self.pitch(), 0.0], "rate_hz": float(args.camera_hz),
                     "encoding": "Rgb8"}
        self.pin = Pinhole(self.info)
        self.previous_v = None

    def mount(self):
        """The vision sensor in the ego's body frame (relative to the model, then from the axle)."""
        x, y, z = self.sim.getObjectPosition(self.camera, self.ego)
        return [x + self.args.rear_axle, y, z + self.args.ground_z]

    def pitch(self):
        """Downward pitch of the sensor's view: its z axis (the view direction) below the ego's x."""
        m = self.sim.getObjectMatrix(self.camera, self.ego)
        view = (m[2], m[6], m[10])  # the sensor's z axis in the ego frame
        return -math.atan2(view[2], math.hypot(view[0], view[1]))

    def state(self, dt):
        ego = Pose(self.sim, self.ego, self.args.rear_axle)
        c, s = math.cos(ego.yaw), math.sin(ego.yaw)
        forward = c * ego.v[0] + s * ego.v[1]
        accel = 0.0 if self.previous_v is None or dt <= 0 else (forward - self.previous_v) / dt
        self.previous_v = forward
        speed = math.hypot(ego.v[0], ego.v[1])
        return ego, speed, {
            "position_in_world_m": [ego.x, ego.y, 0.0], "yaw_in_world_rad": ego.yaw, "pitch_rad": 0.0,
            "roll_rad": 0.0, "velocity_in_world_mps": ego.v, "acceleration_in_body_mps2": [accel, 0.0, 0.0],
            "yaw_rate_radps": ego.yaw_rate, "speed_mps": speed, "lane": -1}

    def objects(self, ego):
        out = []
        length, width, height = self.args.vehicle_size
        for i, handle in enumerate(self.traffic):
            o = Pose(self.sim, handle, length / 2)  # its rear face
            x, y = ego.to_body(o.x, o.y)
            rel = (o.v[0] - ego.v[0], o.v[1] - ego.v[1])
            c, s = math.cos(ego.yaw), math.sin(ego.yaw)
            vx, vy = c * rel[0] + s * rel[1] + ego.yaw_rate * y, -s * rel[0] + c * rel[1] - ego.yaw_rate * x
            box, visible = self.pin.rear_box(x, y, width, height) if x > 0 else (None, 0.0)
            out.append({
                "id": i + 1, "class": "Car", "size_m": [length, width, height], "lane": -1,
                "position_in_world_m": [o.x, o.y, 0.0], "yaw_in_world_rad": o.yaw, "velocity_in_world_mps": o.v,
                "position_in_ego_m": [x, y, height / 2], "yaw_in_ego_rad": o.yaw - ego.yaw,
                "velocity_in_ego_mps": [vx, vy, 0.0], "bbox": box, "visible_fraction": visible,
                "brake_lights": False})
        return out

    def frame(self):
        data, (w, h) = self.sim.getVisionSensorImg(self.camera)
        rgb = np.frombuffer(data, np.uint8).reshape(h, w, 3)[::-1]  # bottom row first -> top first
        return {"width": w, "height": h, "encoding": "Rgb8", "data": np.ascontiguousarray(rgb).tobytes()}

    def apply(self, cmd):
        if cmd is not None:
            self.sim.callScriptFunction(self.args.control_function, self.script,
                                        cmd["throttle"], cmd["brake"], cmd["steer"])

    def publish(self, k, dt, rtf):
        ego, speed, state = self.state(dt)
        self.side.publish_ego(k, speed, state, rtf)
        if k % self.every == 0:
            self.side.publish_frame(k, self.frame(), self.objects(ego))

    def run(self, stop):
        side, sim = self.side, self.sim
        hz, dt = side.hz, 1.0 / side.hz
        self.every = max(1, round(hz / self.args.camera_hz))
        side.start(self.info, None, scenario="coppeliasim")
        steps, rtf, k = round(self.args.duration * hz), RealTimeFactor(), 0
        sim.setStepping(True)
        sim.startSimulation()
        started = time.monotonic()
        while k <= steps and not stop.is_set():
            self.publish(k, dt, rtf(k * dt))
            if k == steps:
                break
            self.apply(side.control(k))
            sim.step()
            k += 1
            if side.mode == "realtime":
                # Paced here: behind the wall clock it steps on at once (the real-time factor
                # says so), ahead of it waits.
                ahead = started + k * dt - time.monotonic()
                if ahead > 0:
                    time.sleep(ahead)
        side.end(k, "stopped" if stop.is_set() else "duration reached")
        return k

    def close(self):
        try:
            self.sim.stopSimulation()
        except zmq.ZMQError:  # interrupted inside a call: the request socket cannot send again
            pass


def triple(text):
    values = [float(v) for v in text.split(",")]
    if len(values) != 3:
        raise argparse.ArgumentTypeError("give length,width,height in metres")
    return values


def parser():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--host", default="127.0.0.1", help="CoppeliaSim's ZMQ remote API host [default: 127.0.0.1]")
    p.add_argument("--port", type=int, default=23000, help="its port [default: 23000]")
    p.add_argument("--timeout", type=float, default=10.0, help="seconds CoppeliaSim may take to answer [default: 10]")
    p.add_argument("--ego", default="/Car", help="the ego vehicle's object path [default: /Car]")
    p.add_argument("--camera", default="/Car/visionSensor", help="its vision sensor [default: /Car/visionSensor]")
    p.add_argument("--traffic", action="append", default=[], metavar="PATH", help="other vehicles (ground truth)")
    p.add_argument("--vehicle-size", type=triple, default=[4.6, 1.85, 1.45], help="L,W,H of the traffic, m")
    p.add_argument("--rear-axle", type=float, default=1.35, help="model origin to rear axle, m [default: 1.35]")
    p.add_argument("--ground-z", type=float, default=0.0, help="model origin above the ground, m [default: 0]")
    p.add_argument("--control-function", default="slipstream_control", help="the ego script's function")
    cli.add_clock_args(p, "lockstep", 3600.0)
    connect.add_args(p)
    return p


def open_sim(args):
    """CoppeliaSim's `sim` object; every call bounded by --timeout (the client waits forever)."""
    client = RemoteAPIClient(args.host, args.port)
    # The client's REQ socket has no receive time-out of its own: a lost server would hang it.
    client.socket.setsockopt(zmq.RCVTIMEO, int(args.timeout * 1000))
    client.socket.setsockopt(zmq.LINGER, 0)
    return client, client.require("sim")


def main():
    """Runs the adapter; exits 1 when CoppeliaSim cannot be reached or stops answering."""
    args = parser().parse_args()
    try:
        client, sim = open_sim(args)
        hz = round(1.0 / sim.getSimulationTimeStep())
    except zmq.Again:
        raise SystemExit(f"coppeliasim adapter: no answer from CoppeliaSim at {args.host}:{args.port} "
                         f"within {args.timeout:g} s (is the ZMQ remote API add-on running?)") from None
    if hz < 50:
        print(f"coppeliasim adapter: the scene's time step gives {hz} Hz; the contract asks vehicle/speed at "
              ">= 50 Hz: set a 10 or 20 ms time step", file=sys.stderr, flush=True)
    session, topics = cli.open_session(args)
    side = SimulatorSide(session, topics, args.mode, hz, args.wait_for or ["acc"], args.step_timeout)

    def make(side):
        adapter = CoppeliaAdapter(side, sim, args)
        print(f"# coppeliasim adapter: {args.mode} at {hz} Hz, ego {args.ego}, on {topics.key('vehicle/speed')}",
              flush=True)
        return adapter

    return cli.run_world(side, session, make, {
        zmq.Again: lambda e: f"coppeliasim adapter: lost CoppeliaSim: no answer within {args.timeout:g} s",
        # The client raises a plain Exception with CoppeliaSim's own words.
        Exception: lambda e: f"coppeliasim adapter: CoppeliaSim refused a call: {e}",
    })

if __name__ == "__main__":
    sys.exit(main())
