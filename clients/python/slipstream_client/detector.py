"""A detector of your own as one function; this module keeps the rest of the node contract
(docs/node-contract.md): it reads camera/front latest-only (a frame replaced before it was read
is skipped, never queued) as numpy arrays, waits for camera/front/info (latched), answers every
frame it processes with one perception/objects message naming that frame (its stamp, sequence
number and publish stamp), also when it found nothing, attaches its name and declares the
node's liveliness token once it listens.

    from slipstream_client.detector import detection, run_detector

    def detect(frame):                          # -> a list of detection(...)
        return []

    run_detector(detect)

`frame.rgb` is a (height, width, 3) uint8 RGB array (read-only), `frame.camera` the camera's
Pinhole (intrinsics and mount: `ground(u, v)` is where a pixel meets the road, in the ego's
body frame). It runs as `slipstream up --detector "python3 my_detector.py"` or `slipstream eval
detect --detector ...` starts it (its connection and name in the environment), or by hand with
the usual connection flags.
"""

import argparse
import os
import threading
import time
from dataclasses import dataclass
from typing import Any, Callable, Dict, List, Optional

import zenoh
import zenoh.ext

from . import cli, connect
from .camera import Pinhole
from .image import frame_array
from .wire import BadPayloads, WireError, decode, encode, encoding_schema


@dataclass
class Frame:
    t_s: float
    seq: int
    rgb: Any
    camera: Pinhole


Detect = Callable[[Frame], List[Dict[str, Any]]]


def detection(box: Dict[str, float], distance_m: float, lateral_offset_m: float, relative_speed_mps: float = 0.0, *,
              cls: str = "Car", confidence: float = 0.5, distance_sigma_m: Optional[float] = None,
              relative_speed_sigma_mps: float = 10.0, track_id: int = 0, brake_lights: bool = False) -> Dict[str, Any]:
    """A Detection body: `box` in the front image (u_min_px, v_min_px, u_max_px, v_max_px),
    the distance along the ego's x axis to the vehicle's rear and its lateral offset (positive
    left), its speed relative to the ego's (negative: closing) and how sure each is (without a
    tracker, say so with a large relative_speed_sigma_mps)."""
    return {"track_id": track_id, "class": cls, "bbox": box, "confidence": confidence, "distance_m": distance_m,
            "lateral_offset_m": lateral_offset_m, "relative_speed_mps": relative_speed_mps,
            "distance_sigma_m": distance_sigma_m if distance_sigma_m is not None else 0.05 * distance_m + 0.5,
            "relative_speed_sigma_mps": relative_speed_sigma_mps, "brake_lights": brake_lights}


class DetectorNode:
    """The node around a `detect` function (see the module doc). `start()` declares everything,
    then the token; `run(stop)` answers frames until `stop` is set."""

    def __init__(self, session: zenoh.Session, topics: Any, detect: Detect, name: str) -> None:
        self.session, self.topics, self.detect, self.name = session, topics, detect, name
        self.bad = BadPayloads()
        self.cond = threading.Condition()
        self.latest: Optional[bytes] = None
        self.camera: Optional[Pinhole] = None
        self.answered = 0
        self.seq = 0
        self.subs: List[Any] = []
        self.pub: Any = None
        self.token: Any = None

    def _on_info(self, sample: zenoh.Sample) -> None:
        try:
            _, _, info = decode(sample.payload.to_bytes(), expected="CameraInfo")
        except WireError as e:
            return self.bad(self.topics.key("camera/front/info"), e)
        with self.cond:
            self.camera = Pinhole(info)
            self.cond.notify_all()

    def _on_frame(self, sample: zenoh.Sample) -> None:
        # Zenoh's thread only hands the frame over: the newest replaces one not yet read.
        with self.cond:
            self.latest = sample.payload.to_bytes()
            self.cond.notify_all()

    def start(self) -> None:
        t = self.topics
        self.subs.append(zenoh.ext.declare_advanced_subscriber(
            self.session, t.key("camera/front/info"), self._on_info,
            history=zenoh.ext.HistoryConfig(detect_late_publishers=True, max_samples=1)))
        self.subs.append(self.session.declare_subscriber(t.key("camera/front"), self._on_frame))
        self.pub = self.session.declare_publisher(t.key("perception/objects"), express=True)
        self.token = self.session.liveliness().declare_token(t.node_key(self.name))

    def run(self, stop: threading.Event) -> int:
        while not stop.is_set():
            with self.cond:
                self.cond.wait_for(lambda: self.latest is not None and self.camera is not None, timeout=0.1)
                payload, camera, self.latest = self.latest, self.camera, None
            if payload is None or camera is None:
                continue
            self.answer(payload, camera)
        return self.answered

    def answer(self, payload: bytes, camera: Pinhole) -> None:
        try:
            header, _, rgb = frame_array(payload)
        except WireError as e:
            return self.bad(self.topics.key("camera/front"), e)
        frame = Frame(header["stamp_sim_ns"] / 1e9, header["seq"], rgb, camera)
        found = self.detect(frame)
        out = {"seq": self.seq, "stamp_sim_ns": header["stamp_sim_ns"], "stamp_pub_ns": time.time_ns()}
        body = {"frame_seq": header["seq"], "frame_stamp_pub_ns": header["stamp_pub_ns"], "detections": list(found)}
        self.pub.put(encode("Detections", out, body), attachment=self.name.encode(),
                     encoding=zenoh.Encoding.APPLICATION_OCTET_STREAM.with_schema(encoding_schema("Detections")))
        self.seq += 1
        self.answered += 1

    def close(self) -> None:
        if self.token is not None:
            self.token.undeclare()
        for s in self.subs:
            s.undeclare()
        if self.pub is not None:
            self.pub.undeclare()


def run_detector(detect: Detect, description: Optional[str] = None,
                 parser: Optional[argparse.ArgumentParser] = None) -> argparse.Namespace:
    """Runs `detect` as the loop's detector until Ctrl-C or SIGTERM; returns the parsed flags
    (give `parser` to add flags of your own)."""
    parser = parser or argparse.ArgumentParser(description=description)
    parser.add_argument("--name", default=os.environ.get("SLIPSTREAM_NODE", "detect"),
                        help="node name (liveliness, attachment) [env: SLIPSTREAM_NODE; default: detect]")
    connect.add_args(parser)
    args = parser.parse_args()
    session, topics = cli.open_session(args)
    node = DetectorNode(session, topics, detect, args.name)
    cli.serve(node, session, lambda: f"# {args.name}: {node.answered} frames answered, {node.bad.count} undecodable inputs")
    return args
