"""The pinhole camera of camera/front/info (docs/wire-format.md, CameraInfo): the info a
simulator announces, and where a point of the ego's body frame lands in the image, which is
how a simulator draws its ground truth's 2D boxes.

Frames: body x forward from the rear axle, y left, z up; the camera at `mount` in it, pitched
down by `pitch`; pixels u right, v down from the top-left corner."""

import math
from typing import Any, Dict, Optional, Sequence, Tuple


def pinhole_info(width: int, height: int, fov_deg: float, mount: Sequence[float] = (1.6, 0.0, 1.35), pitch_deg: float = 3.0,
                 rate_hz: float = 20.0, encoding: str = "Rgb8") -> Dict[str, Any]:
    """A CameraInfo body: square pixels, principal point at the centre, f from the field of view."""
    f = (width / 2) / math.tan(math.radians(fov_deg) / 2)
    return {"width": width, "height": height, "fx_px": f, "fy_px": f, "cx_px": width / 2, "cy_px": height / 2,
            "horizontal_fov_rad": math.radians(fov_deg), "mount_position_in_ego_m": [float(m) for m in mount],
            "mount_roll_pitch_yaw_rad": [0.0, math.radians(pitch_deg), 0.0], "rate_hz": float(rate_hz),
            "encoding": encoding}


class Pinhole:
    """Projection with a CameraInfo body's numbers (roll and yaw of the mount taken as 0)."""

    def __init__(self, info: Dict[str, Any]) -> None:
        self.info = info
        self.w, self.h = info["width"], info["height"]
        self.fx, self.fy, self.cx, self.cy = info["fx_px"], info["fy_px"], info["cx_px"], info["cy_px"]
        self.mount = info["mount_position_in_ego_m"]
        self.pitch = info["mount_roll_pitch_yaw_rad"][1]

    def project(self, x: float, y: float, z: float) -> Optional[Tuple[float, float]]:
        """Pixel (u, v) of a point in the ego body frame, or None when it is behind the camera."""
        px, py, pz = x - self.mount[0], y - self.mount[1], z - self.mount[2]
        depth = px * math.cos(self.pitch) - pz * math.sin(self.pitch)
        if depth < 0.5:
            return None
        up = px * math.sin(self.pitch) + pz * math.cos(self.pitch)
        return self.cx - self.fx * py / depth, self.cy - self.fy * up / depth

    def ground(self, u: float, v: float) -> Optional[Tuple[float, float]]:
        """The point (x, y) of the flat road (z = 0) in the ego body frame that pixel (u, v)
        sees, or None at or above the horizon: project()'s inverse on the ground."""
        a = (self.cy - v) / self.fy
        s, c = math.sin(self.pitch), math.cos(self.pitch)
        if s - a * c <= 1e-9:
            return None
        pz = -self.mount[2]
        px = -pz * (c + a * s) / (s - a * c)
        depth = px * c - pz * s
        py = -(u - self.cx) * depth / self.fx
        return px + self.mount[0], py + self.mount[1]

    def horizon_v(self) -> float:
        """The image row of the horizon (points far ahead at any height)."""
        return self.cy - self.fy * math.tan(self.pitch)

    def rear_box(self, x: float, y: float, width_m: float, height_m: float) -> Tuple[Optional[Dict[str, float]], float]:
        """The image box of a vehicle's rear face centred at (x, y) on the ground, clipped to the
        image, and the share of it inside: (BoundingBox2d body or None, visible fraction)."""
        a = self.project(x, y + width_m / 2, height_m)
        b = self.project(x, y - width_m / 2, 0.0)
        if a is None or b is None:
            return None, 0.0
        (u0, v0), (u1, v1) = a, b
        area = max((u1 - u0) * (v1 - v0), 1e-9)
        cu0, cv0, cu1, cv1 = max(u0, 0.0), max(v0, 0.0), min(u1, float(self.w)), min(v1, float(self.h))
        if cu1 <= cu0 or cv1 <= cv0:
            return None, 0.0
        box = {"u_min_px": cu0, "v_min_px": cv0, "u_max_px": cu1, "v_max_px": cv1}
        return box, (cu1 - cu0) * (cv1 - cv0) / area
