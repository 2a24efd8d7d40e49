#!/usr/bin/env python3
"""Receives the front camera (camera/front) as numpy arrays; shows them with OpenCV if it is
installed and a display is available (--show), and prints what it got.

    python3 clients/python/examples/camera_numpy.py --count 20      # next to `slipstream up`
    python3 clients/python/examples/camera_numpy.py --show          # needs opencv-python

Frames are (height, width, 3) uint8 RGB arrays. A raw frame's array is a view of the bytes
Zenoh handed over: one copy (Zenoh's buffer to Python bytes), none after it. The intrinsics
come once from camera/front/info, which the simulator latches for late subscribers."""

import argparse
import os
import threading
import time

import _path  # noqa: F401  (source checkout)

import zenoh.ext

from slipstream_client import BadPayloads, WireError, cli, connect, decode
from slipstream_client.image import frame_array


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--count", type=int, default=0, help="stop after N frames [default: run until Ctrl-C]")
    parser.add_argument("--show", action="store_true", help="show frames in an OpenCV window")
    connect.add_args(parser)
    args = parser.parse_args()
    cv2 = None
    if args.show:
        try:
            import cv2
        except ImportError:
            raise SystemExit("--show needs OpenCV: pip install opencv-python") from None
        if not os.environ.get("DISPLAY") and os.name == "posix":
            raise SystemExit("--show needs a display (DISPLAY is not set); leave --show out to print frames")
    session, topics = cli.open_session(args)
    latest = {"frame": None}
    cond = threading.Condition()
    stats = {"n": 0}
    bad = BadPayloads()

    def on_info(sample):
        try:
            _, _, info = decode(sample.payload.to_bytes(), expected="CameraInfo")
        except WireError as e:
            return bad(topics.key("camera/front/info"), e)
        print(f"# camera {info['width']}x{info['height']} at {info['rate_hz']:g} Hz, fx {info['fx_px']:.1f} px, "
              f"{info['encoding']}", flush=True)

    def on_frame(sample):
        # Zenoh's callback thread only hands the frame over; the main thread does the work,
        # and a slow reader skips frames instead of queueing them.
        with cond:
            latest["frame"] = sample.payload.to_bytes()
            cond.notify()

    info_sub = zenoh.ext.declare_advanced_subscriber(
        session, topics.key("camera/front/info"), on_info,
        history=zenoh.ext.HistoryConfig(detect_late_publishers=True))
    sub = session.declare_subscriber(topics.key("camera/front"), on_frame)
    print(f"# listening on {topics.key('camera/front')}", flush=True)
    try:
        while not args.count or stats["n"] < args.count:
            with cond:
                cond.wait_for(lambda: latest["frame"] is not None, timeout=0.5)
                payload, latest["frame"] = latest["frame"], None
            if payload is None:
                continue
            try:
                header, frame, pixels = frame_array(payload)
            except WireError as e:
                bad(topics.key("camera/front"), e)
                continue
            stats["n"] += 1
            age_ms = (time.time_ns() - header["stamp_pub_ns"]) / 1e6
            mean = pixels.reshape(-1, 3).mean(axis=0)
            print(f"frame seq {header['seq']:6d} t={header['stamp_sim_ns'] / 1e9:8.2f} s  {pixels.shape} "
                  f"{pixels.dtype} {frame['encoding']}  mean RGB ({mean[0]:.0f}, {mean[1]:.0f}, {mean[2]:.0f})  "
                  f"age {age_ms:6.2f} ms", flush=True)
            if cv2 is not None:
                cv2.imshow("slipstream camera/front", pixels[:, :, ::-1])
                if cv2.waitKey(1) == 27:  # Esc
                    break
    except KeyboardInterrupt:
        pass
    finally:
        sub.undeclare()
        info_sub.undeclare()
        session.close()


if __name__ == "__main__":
    main()
