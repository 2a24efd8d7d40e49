"""The small world the simulator stand-ins (carla_standin.py, coppeliasim_standin.py) move and
draw, in slipstream's frames (x along the road, y left): a straight three-lane road, the ego in
the middle lane at 25 m/s, a car 45 m ahead at 22 m/s that slows to 12 m/s at 12 s and speeds
up again at 25 s, a faster car in the left lane. The ego is a point mass whose pedals follow
the command through a 0.3 s lag; the camera is the reference simulator's renderer."""

import pathlib
import sys

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[2] / "clients" / "python" / "examples"))
from reference_sim import CAR_REAR_OVERHANG, CAR_SIZE, Camera, lane_d, resistance  # noqa: E402, F401

HALF_LENGTH = CAR_SIZE[0] / 2


class Mover:
    """A vehicle by its centre: x, y (m), speed v (m/s) along x."""

    def __init__(self, vid, x, lane, v, profile=(), hero=False):
        self.id, self.x, self.y, self.v, self.a = vid, x, lane_d(lane), v, 0.0
        self.profile, self.hero = list(profile), hero
        self.command = (0.0, 0.0)  # throttle, brake: what the ego is asked
        self.pedals = [resistance(v) / min(6500.0, 110000.0 / max(v, 1.0)), 0.0]

    @property
    def braking(self):
        return self.a < -0.5

    def step(self, t, dt):
        if self.hero:
            lag = min(1.0, dt / 0.3)
            self.pedals = [p + (c - p) * lag for p, c in zip(self.pedals, self.command)]
            drive = self.pedals[0] * min(6500.0, 110000.0 / max(self.v, 1.0))
            self.a = (drive - resistance(self.v)) / 1500.0 - self.pedals[1] * 9.0
        else:
            target, rate = self.v, 0.0
            for start, speed, accel in self.profile:
                if t >= start:
                    target, rate = speed, accel
            self.a = max(-rate, min(rate, (target - self.v) / dt)) if rate else 0.0
        self.v = max(0.0, self.v + self.a * dt)
        self.x += self.v * dt


def road_world(ego_x=0.0):
    """[ego, lead, other]: the ego's centre at ego_x."""
    return [Mover(1, ego_x, 1, 25.0, hero=True),
            Mover(2, ego_x + 45.0 + CAR_SIZE[0], 1, 22.0, [(12, 12.0, 3.0), (25, 22.0, 1.0)]),
            Mover(3, ego_x + 75.0 + CAR_SIZE[0], 2, 26.0)]


def draw(camera, movers):
    """The ego's camera image (H x W x 3 RGB8, top row first)."""
    ego = next(m for m in movers if m.hero)
    rear_axle = ego.x - HALF_LENGTH + CAR_REAR_OVERHANG
    others = [{"id": m.id, "x": m.x - HALF_LENGTH - rear_axle, "y": m.y - ego.y, "color": (150, 32, 36),
               "braking": m.braking} for m in movers if not m.hero]
    rgb, _ = camera.render(rear_axle, [o for o in others if o["x"] > CAR_SIZE[0] - CAR_REAR_OVERHANG])
    return rgb


def camera(width, height, fov_deg, mount, pitch_deg):
    return Camera(width, height, 20.0, fov_deg, mount, pitch_deg)

