#!/usr/bin/env python3
"""A detector of your own in about 40 lines, on numpy and OpenCV (opencv-python-headless from
a registry; nothing downloaded at run time): the dark band a vehicle makes where it meets the
road (its shadow and tyres, darker than the asphalt around them) found below the horizon,
placed on the flat road through the camera's intrinsics, matched to the last frame's for its
relative speed. A teaching detector: `slipstream eval detect --detector` scores it next to
slipstream-detect (docs/own-node.md).

    slipstream eval detect --detector 'python3 clients/python/examples/own_detect.py'
    slipstream up --mode lockstep --detector 'python3 clients/python/examples/own_detect.py'
"""

import cv2
import numpy as np

import _path  # noqa: F401  (source checkout)

from slipstream_client.detector import detection, run_detector

DARK = 0.6           # a pixel darker than this share of the road's brightness is shadow or tyre
WIDTH_M = (1.2, 3.2)  # how wide a vehicle's dark band may be
last = {"t_s": None, "seen": []}


def detect(frame):
    cam, grey = frame.camera, cv2.cvtColor(np.ascontiguousarray(frame.rgb), cv2.COLOR_RGB2GRAY)
    top = int(cam.horizon_v()) + 2
    road = float(np.median(grey[-grey.shape[0] // 8:, grey.shape[1] // 3: 2 * grey.shape[1] // 3]))
    mask = (grey[top:] < DARK * road).astype(np.uint8)
    mask = cv2.morphologyEx(mask, cv2.MORPH_CLOSE, np.ones((3, 5), np.uint8))
    contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
    found, dt = [], None if last["t_s"] is None else frame.t_s - last["t_s"]
    for c in contours:
        u, v, w, h = cv2.boundingRect(c)
        left, right = cam.ground(u, top + v + h), cam.ground(u + w, top + v + h)
        if left is None or right is None or not WIDTH_M[0] <= left[1] - right[1] <= WIDTH_M[1]:
            continue
        x, y = left[0], (left[1] + right[1]) / 2
        box, _ = cam.rear_box(x, y, left[1] - right[1], 1.5)
        near = [d for d in last["seen"] if abs(d[0] - x) < 3.0 and abs(d[1] - y) < 1.0]
        rel = (x - near[0][0]) / dt if near and dt else 0.0
        if box is not None:
            found.append(detection(box, x, y, rel, relative_speed_sigma_mps=3.0 if near else 10.0))
    last["t_s"], last["seen"] = frame.t_s, [(d["distance_m"], d["lateral_offset_m"]) for d in found]
    return found


if __name__ == "__main__":
    run_detector(detect, description=__doc__)
