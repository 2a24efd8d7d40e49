"""slipstream wire format (version 5) in pure Python, written from docs/wire-format.md alone.

decode(payload) -> (kind_name, header, body) and encode(kind_name, header, body) -> bytes.
Bodies are dicts keyed by the field names of the doc; enums are their variant names
(SimEventKind variants are {"variant": name, **fields}); bytes fields are bytes.
Decoding is strict, like the Rust side: any malformed payload raises WireError.
"""

import logging
import math
import struct
import threading
from typing import Any, Dict, Optional, Tuple

WIRE_VERSION = 5
# The most pixels a camera frame may have (8192 x 8192).
MAX_FRAME_PIXELS = 8192 * 8192


class WireError(ValueError):
    """A payload that is not a valid slipstream message of this wire version."""


log = logging.getLogger("slipstream_client")


class BadPayloads:
    """Counts undecodable payloads and logs the 1st, 10th, 100th, ... of them as warnings
    (logger "slipstream_client"): a client keeps running on bad input and says so without
    flooding its log, as the nodes do. Callable from any Zenoh callback thread:
    bad(key, error)."""

    def __init__(self) -> None:
        self.count = 0
        self._lock = threading.Lock()

    def __call__(self, key: str, error: Exception) -> None:
        with self._lock:
            self.count += 1
            n = self.count
        if str(n).rstrip("0") == "1":  # 1, 10, 100, ...
            log.warning("%s: undecodable payload #%d: %s", key, n, error)


# Type language: "u8" "u32" "u64" "i32" "f32" "f64" "bool" "str" "bytes",
# ("opt", T), ("seq", T), ("arr", T, N), ("enum", [names]), ("struct", NAME), ("variants", NAME).
VEC3 = ("arr", "f64", 3)
IMAGE_ENCODING = ("enum", ["Rgb8", "Jpeg", "Png", "Lz4"])
OBJECT_CLASS = ("enum", ["Unknown", "Car", "Van", "Truck", "Motorcycle"])

STRUCTS = {
    "Header": [("seq", "u64"), ("stamp_sim_ns", "u64"), ("stamp_pub_ns", "u64")],
    "Speed": [("speed_mps", "f64")],
    "ControlCommand": [
        ("throttle", "f32"), ("brake", "f32"), ("steer", "f32"), ("answers_step", ("opt", "u64")),
        ("perception_stamp_pub_ns", ("opt", "u64")),
    ],
    "ControlTiming": [("command_stamp_pub_ns", "u64"), ("applied_ns", "u64")],
    "VehicleState": [
        ("step", "u64"), ("position_in_world_m", VEC3), ("yaw_in_world_rad", "f64"), ("pitch_rad", "f64"),
        ("roll_rad", "f64"), ("velocity_in_world_mps", VEC3), ("acceleration_in_body_mps2", VEC3),
        ("yaw_rate_radps", "f64"), ("speed_mps", "f64"), ("lane", "i32"), ("applied", ("struct", "ControlCommand")),
        ("control_timing", ("opt", ("struct", "ControlTiming"))),
    ],
    "CameraFrame": [("width", "u32"), ("height", "u32"), ("encoding", IMAGE_ENCODING), ("data", "bytes")],
    "CameraInfo": [
        ("width", "u32"), ("height", "u32"), ("fx_px", "f64"), ("fy_px", "f64"), ("cx_px", "f64"), ("cy_px", "f64"),
        ("horizontal_fov_rad", "f64"), ("mount_position_in_ego_m", VEC3), ("mount_roll_pitch_yaw_rad", VEC3),
        ("rate_hz", "f64"), ("encoding", IMAGE_ENCODING),
    ],
    "BoundingBox2d": [("u_min_px", "f32"), ("v_min_px", "f32"), ("u_max_px", "f32"), ("v_max_px", "f32")],
    "GroundTruthObject": [
        ("id", "u32"), ("class", OBJECT_CLASS), ("size_m", VEC3), ("lane", "i32"), ("position_in_world_m", VEC3),
        ("yaw_in_world_rad", "f64"), ("velocity_in_world_mps", VEC3), ("position_in_ego_m", VEC3),
        ("yaw_in_ego_rad", "f64"), ("velocity_in_ego_mps", VEC3), ("bbox", ("opt", ("struct", "BoundingBox2d"))),
        ("visible_fraction", "f32"), ("brake_lights", "bool"),
    ],
    "GroundTruthObjects": [("step", "u64"), ("objects", ("seq", ("struct", "GroundTruthObject")))],
    "Detection": [
        ("track_id", "u32"), ("class", OBJECT_CLASS), ("bbox", ("struct", "BoundingBox2d")), ("confidence", "f32"),
        ("distance_m", "f64"), ("lateral_offset_m", "f64"), ("relative_speed_mps", "f64"),
        ("distance_sigma_m", "f64"), ("relative_speed_sigma_mps", "f64"), ("brake_lights", "bool"),
    ],
    "Detections": [("frame_seq", "u64"), ("frame_stamp_pub_ns", "u64"), ("detections", ("seq", ("struct", "Detection")))],
    "SimClock": [("step", "u64"), ("real_time_factor", "f32"), ("mode", ("enum", ["Realtime", "Fast", "Lockstep"])), ("physics_hz", "f64")],
    "SimEvent": [("kind", ("variants", "SimEventKind"))],
    "LeadInfo": [("id", "u32"), ("gap_m", "f64"), ("desired_gap_m", "f64"), ("relative_speed_mps", "f64"), ("ttc_s", ("opt", "f64"))],
    "AccStatus": [
        ("mode", ("enum", ["Off", "Speed", "Follow", "Stale", "Emergency"])), ("set_speed_mps", "f64"), ("time_gap_s", "f64"),
        ("target_accel_mps2", "f64"), ("lead", ("opt", ("struct", "LeadInfo"))),
        ("warnings", ("seq", ("enum", ["ForwardCollision", "StaleSpeed", "StalePerception", "PerceptionLost"]))),
    ],
    "AccCommand": [("enable", ("opt", "bool")), ("set_speed_mps", ("opt", "f64")), ("time_gap_s", ("opt", "f64"))],
    "Curve": [("start_m", "f64"), ("length_m", "f64"), ("radius_m", "f64")],
    "LaneEnd": [("lane", "u32"), ("end_m", "f64"), ("taper_m", "f64")],
    "RoadMap": [
        ("lanes", "u32"), ("lane_width_m", "f64"), ("length_m", "f64"), ("curves", ("seq", ("struct", "Curve"))),
        ("lane_ends", ("seq", ("struct", "LaneEnd"))),
    ],
    "EgoInfo": [
        ("class", OBJECT_CLASS), ("size_m", VEC3), ("rear_overhang_m", "f64"), ("wheelbase_m", "f64"),
        ("mass_kg", "f64"), ("max_power_w", "f64"), ("max_drive_force_n", "f64"), ("max_brake_decel_mps2", "f64"),
        ("drag_area_m2", "f64"), ("rolling_coeff", "f64"), ("actuator_lag_s", "f64"), ("set_speed_mps", "f64"),
        ("time_gap_s", ("opt", "f64")),
    ],
}

VARIANTS = {
    "SimEventKind": [
        ("ScenarioStart", [("name", "str"), ("seed", "u64")]),
        ("ScenarioEnd", [("reason", "str"), ("success", "bool")]),
        ("Collision", [("other_id", "u32"), ("relative_speed_mps", "f64")]),
        ("ControlTimeout", [("late", ("seq", "str"))]),
    ],
}

KINDS = {
    1: "Speed", 2: "VehicleState", 3: "ControlCommand", 4: "CameraFrame", 5: "CameraInfo", 6: "GroundTruthObjects",
    7: "Detections", 8: "SimClock", 9: "SimEvent", 10: "AccStatus", 11: "AccCommand", 12: "RoadMap",
    13: "EgoInfo",
}
KIND_IDS = {name: kid for kid, name in KINDS.items()}

# Default keys (docs/wire-format.md); a namespace prefixes them, config may remap them.
DEFAULT_KEYS = {
    "vehicle/speed": "Speed", "vehicle/state": "VehicleState", "vehicle/control": "ControlCommand",
    "camera/front": "CameraFrame", "camera/front/info": "CameraInfo", "objects": "GroundTruthObjects",
    "perception/objects": "Detections", "sim/clock": "SimClock", "sim/events": "SimEvent",
    "acc/status": "AccStatus", "acc/command": "AccCommand", "sim/road": "RoadMap",
    "camera/narrow": "CameraFrame", "camera/narrow/info": "CameraInfo", "sim/ego": "EgoInfo",
}

_VARINT_MAX = {"u32": 5, "u64": 10}
_BITS = {"u32": 32, "u64": 64}


class _Reader:
    """Reads postcard values of the type language above; `structs` and `variants` name the
    types it knows (this version's by default, a recording's own in mcap_decoder)."""

    def __init__(self, data, copy=True, structs=None, variants=None):
        self.data = memoryview(data)
        self.at = 0
        self.copy = copy
        self.structs = STRUCTS if structs is None else structs
        self.variants = VARIANTS if variants is None else variants

    def take(self, n):
        if self.at + n > len(self.data):
            raise WireError("truncated: payload ended inside a field")
        chunk = self.data[self.at:self.at + n]
        self.at += n
        return chunk

    def varint(self, ty):
        value, shift = 0, 0
        for i in range(_VARINT_MAX[ty]):
            b = self.take(1)[0]
            value |= (b & 0x7F) << shift
            if not b & 0x80:
                if value >= 1 << _BITS[ty]:
                    raise WireError(f"varint too large for {ty}")
                return value
            shift += 7
        raise WireError(f"varint longer than {ty} allows")

    def read(self, ty):
        if ty == "u8":
            return self.take(1)[0]
        if ty in ("u32", "u64"):
            return self.varint(ty)
        if ty == "i32":
            z = self.varint("u32")
            return (z >> 1) ^ -(z & 1)
        if ty == "f32":
            return struct.unpack("<f", self.take(4))[0]
        if ty == "f64":
            return struct.unpack("<d", self.take(8))[0]
        if ty == "bool":
            b = self.take(1)[0]
            if b > 1:
                raise WireError(f"bool byte {b} is neither 0 nor 1")
            return b == 1
        if ty == "bytes":
            chunk = self.take(self.varint("u64"))
            return bytes(chunk) if self.copy else chunk
        if ty == "str":
            raw = bytes(self.take(self.varint("u64")))
            try:
                return raw.decode("utf-8")
            except UnicodeDecodeError as e:
                raise WireError(f"invalid UTF-8: {e}") from None
        tag = ty[0]
        if tag == "opt":
            b = self.take(1)[0]
            if b > 1:
                raise WireError(f"option tag {b} is neither 0 nor 1")
            return self.read(ty[1]) if b == 1 else None
        if tag == "seq":
            n = self.varint("u64")
            if n > len(self.data) - self.at:  # every element takes at least one byte
                raise WireError("truncated: sequence longer than the payload")
            return [self.read(ty[1]) for _ in range(n)]
        if tag == "arr":
            return [self.read(ty[1]) for _ in range(ty[2])]
        if tag == "enum":
            i = self.varint("u32")
            if i >= len(ty[1]):
                raise WireError(f"enum index {i} names no variant")
            return ty[1][i]
        if tag == "struct":
            return {name: self.read(fty) for name, fty in self.structs[ty[1]]}
        if tag == "variants":
            i = self.varint("u32")
            variants = self.variants[ty[1]]
            if i >= len(variants):
                raise WireError(f"enum index {i} names no variant")
            name, fields = variants[i]
            return {"variant": name, **{f: self.read(fty) for f, fty in fields}}
        raise AssertionError(f"unknown type {ty}")


def _varint(value):
    out = bytearray()
    while True:
        b = value & 0x7F
        value >>= 7
        if value:
            out.append(b | 0x80)
        else:
            out.append(b)
            return bytes(out)


def _write(out, ty, v):
    if ty == "u8":
        out.append(v)
    elif ty in ("u32", "u64"):
        out += _varint(v)
    elif ty == "i32":
        out += _varint(((v << 1) ^ (v >> 31)) & 0xFFFFFFFF)
    elif ty == "f32":
        out += struct.pack("<f", v)
    elif ty == "f64":
        out += struct.pack("<d", v)
    elif ty == "bool":
        out.append(1 if v else 0)
    elif ty == "bytes":
        out += _varint(len(v)) + bytes(v)
    elif ty == "str":
        raw = v.encode("utf-8")
        out += _varint(len(raw)) + raw
    elif ty[0] == "opt":
        if v is None:
            out.append(0)
        else:
            out.append(1)
            _write(out, ty[1], v)
    elif ty[0] == "seq":
        out += _varint(len(v))
        for item in v:
            _write(out, ty[1], item)
    elif ty[0] == "arr":
        if len(v) != ty[2]:
            raise WireError(f"array needs {ty[2]} values, got {len(v)}")
        for item in v:
            _write(out, ty[1], item)
    elif ty[0] == "enum":
        out += _varint(ty[1].index(v))
    elif ty[0] == "struct":
        for name, fty in STRUCTS[ty[1]]:
            _write(out, fty, v[name])
    elif ty[0] == "variants":
        names = [n for n, _ in VARIANTS[ty[1]]]
        i = names.index(v["variant"])
        out += _varint(i)
        for name, fty in VARIANTS[ty[1]][i][1]:
            _write(out, fty, v[name])
    else:
        raise AssertionError(f"unknown type {ty}")


def _in(v, lo, hi):
    """lo <= v <= hi; False for NaN (every comparison with NaN is)."""
    return lo <= v <= hi


def _check(kind, body):
    """The value rules of docs/wire-format.md ("Value rules")."""
    if kind == "CameraFrame":
        if body["width"] == 0 or body["height"] == 0:
            raise WireError("frame size is empty")
        pixels = body["width"] * body["height"]
        if pixels > MAX_FRAME_PIXELS:
            raise WireError(f"{body['width']}x{body['height']} is more than {MAX_FRAME_PIXELS} pixels")
        n = len(body["data"])
        if body["encoding"] == "Rgb8" and n != pixels * 3:
            raise WireError("Rgb8 frame length does not match its size")
        if body["encoding"] == "Lz4" and (n == 0 or n * 255 + 16 < pixels * 3):
            raise WireError(f"{n} bytes of Lz4 cannot expand to {pixels * 3}")
        if body["encoding"] in ("Jpeg", "Png") and n == 0:
            raise WireError(f"empty {body['encoding']} frame")
    elif kind == "ControlCommand":
        for f, lo, hi in (("throttle", 0, 1), ("brake", 0, 1), ("steer", -1, 1)):
            if not _in(body[f], lo, hi):
                raise WireError(f"{f} {body[f]} is outside {lo}..{hi}")
    elif kind == "CameraInfo":
        if body["width"] == 0 or body["height"] == 0:
            raise WireError("image size is empty")
        if not (body["fx_px"] > 0 and body["fy_px"] > 0):
            raise WireError(f"focal lengths must be positive, got fx={body['fx_px']} fy={body['fy_px']}")
    elif kind == "Detections":
        for d in body["detections"]:
            if not _in(d["confidence"], 0, 1):
                raise WireError(f"track {d['track_id']}: confidence {d['confidence']} is outside 0..1")
            if not (d["distance_sigma_m"] >= 0 and d["relative_speed_sigma_mps"] >= 0):
                raise WireError(f"track {d['track_id']}: standard deviations must be 0 or more")
    elif kind == "AccCommand":
        v, h = body["set_speed_mps"], body["time_gap_s"]
        if v is not None and not (math.isfinite(v) and v >= 0):
            raise WireError(f"set_speed_mps {v} must be a finite value >= 0")
        if h is not None and not (math.isfinite(h) and h > 0):
            raise WireError(f"time_gap_s {h} must be a finite value > 0")
    elif kind == "RoadMap":
        _check_road(body)
    elif kind == "EgoInfo":
        _check_ego(body)


def _check_ego(ego):
    length, width, height = ego["size_m"]
    positive = {"length": length, "width": width, "height": height}
    positive.update({k: ego[k] for k in ("wheelbase_m", "mass_kg", "max_power_w", "max_drive_force_n",
                                         "max_brake_decel_mps2")})
    for name, v in positive.items():
        if not (math.isfinite(v) and v > 0):
            raise WireError(f"{name} {v} must be a finite value > 0")
    for name in ("rear_overhang_m", "drag_area_m2", "rolling_coeff", "actuator_lag_s", "set_speed_mps"):
        if not (math.isfinite(ego[name]) and ego[name] >= 0):
            raise WireError(f"{name} {ego[name]} must be a finite value >= 0")
    h = ego["time_gap_s"]
    if h is not None and not (math.isfinite(h) and h > 0):
        raise WireError(f"time_gap_s {h} must be a finite value > 0")


def _check_road(road):
    if not _in(road["lanes"], 1, 8):
        raise WireError(f"road.lanes: {road['lanes']} lanes (1 to 8)")
    if not _in(road["lane_width_m"], 2.0, 6.0):
        raise WireError(f"road.lane_width_m: {road['lane_width_m']} m (2 to 6)")
    if not _in(road["length_m"], 100.0, 100_000.0):
        raise WireError(f"road.length_m: {road['length_m']} m (100 m to 100 km)")
    for i, c in enumerate(road["curves"]):
        if not (math.isfinite(c["radius_m"]) and abs(c["radius_m"]) >= 30):
            raise WireError(f"road.curves[{i}].radius_m: radius {c['radius_m']} m is too tight")
        if not (math.isfinite(c["start_m"]) and math.isfinite(c["length_m"]) and c["start_m"] >= 0 and c["length_m"] > 0):
            raise WireError(f"road.curves[{i}]: start_m must be >= 0 and length_m > 0")
    for i, e in enumerate(road["lane_ends"]):
        if road["lanes"] < 2 or e["lane"] not in (0, road["lanes"] - 1):
            raise WireError(f"road.lane_ends[{i}].lane: lane {e['lane']} is not an outer lane")
        if not (math.isfinite(e["taper_m"]) and e["taper_m"] >= 20 and e["taper_m"] <= e["end_m"] <= road["length_m"]):
            raise WireError(f"road.lane_ends[{i}]: end_m {e['end_m']} and taper_m {e['taper_m']}")
        if any(o["lane"] == e["lane"] for o in road["lane_ends"][:i]):
            raise WireError(f"road.lane_ends[{i}].lane: lane {e['lane']} ends twice")


def decode(payload: bytes, expected: Optional[str] = None, copy: bool = True) -> Tuple[str, Dict[str, int], Dict[str, Any]]:
    """Decodes one payload strictly. Returns (kind, header, body).

    copy=False leaves bytes fields (camera pixels) as memoryviews into `payload` instead of
    copying them: numpy.frombuffer then reads the pixels where they are."""
    if len(payload) == 0:
        raise WireError("empty payload")
    if payload[0] != WIRE_VERSION:
        raise WireError(f"unknown wire version {payload[0]}")
    if len(payload) < 2:
        raise WireError("truncated in the preamble")
    kind = KINDS.get(payload[1])
    if kind is None:
        raise WireError(f"unknown message kind {payload[1]}")
    if expected is not None and kind != expected:
        raise WireError(f"payload holds a {kind} message, expected {expected}")
    r = _Reader(payload, copy)
    r.at = 2
    header = r.read(("struct", "Header"))
    body = r.read(("struct", kind))
    if r.at != len(payload):
        raise WireError(f"{len(payload) - r.at} trailing bytes after a complete message")
    _check(kind, body)
    return kind, header, body


def encode(kind: str, header: Dict[str, int], body: Dict[str, Any]) -> bytes:
    """Encodes a message; header is {"seq", "stamp_sim_ns", "stamp_pub_ns"}."""
    out = bytearray([WIRE_VERSION, KIND_IDS[kind]])
    _write(out, ("struct", "Header"), header)
    _write(out, ("struct", kind), body)
    return bytes(out)


def encoding_schema(kind: str) -> str:
    """The Zenoh encoding schema every sample of `kind` carries."""
    return f"slipstream/{kind}/v{WIRE_VERSION}"
