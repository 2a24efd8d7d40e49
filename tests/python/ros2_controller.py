"""A ROS 2 controller stand-in for a loop file's `controller: { ..., ros2: true }`, written on
zenoh-ros2-sdk (an rmw_zenoh implementation in Python we did not write: its keys, liveliness
tokens, attachments and CDR), since no ROS 2 install or rmw_zenoh is here. As an rclpy node on
rmw_zenoh would, it reads its Zenoh session config from ZENOH_SESSION_CONFIG_URI (which the
loop sets), subscribes to vehicle/odometry and answers each odometry message with one
ackermann_msgs/msg/AckermannDriveStamped on vehicle/ackermann_cmd (both in the ROS namespace
SLIPSTREAM_ROS_NAMESPACE names, as `__ns:=` would put them) stamped with the
odometry's header.stamp: a cruise control toward --speed m/s. Prints how many it answered.

    python3 ros2_controller.py --msgs DIR [--speed 20] [--stamp odometry|zero]

DIR holds the message definitions as DIR/<package>/msg/<Name>.msg (zenoh-ros2-sdk's registry
layout; nothing is downloaded). `--stamp zero` stamps every command with time 0: a broken
controller, for the bridge's refusals."""

import argparse
import json
import os
import signal
import sys
import threading

from zenoh_ros2_sdk import ROS2Publisher, ROS2Subscriber, get_registry


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--msgs", required=True, help="message definitions, DIR/<package>/msg/<Name>.msg")
    p.add_argument("--speed", type=float, default=20.0, help="the speed to hold, m/s [default: 20]")
    p.add_argument("--stamp", choices=("odometry", "zero"), default="odometry")
    args = p.parse_args()
    get_registry(args.msgs)
    # The SDK dials a router at router_ip:port; the loop's config says whom to dial instead.
    with open(os.environ["ZENOH_SESSION_CONFIG_URI"]) as f:
        dial = json.load(f)["connect"]["endpoints"]
    os.environ["ZENOH_CONFIG_OVERRIDE"] = "connect/endpoints=" + json.dumps(dial)
    answered, done = [0], threading.Event()
    signal.signal(signal.SIGINT, lambda *_: done.set())
    signal.signal(signal.SIGTERM, lambda *_: done.set())
    # In the ROS namespace the loop names, as a node launched with `--ros-args -r __ns:=...`.
    under = os.environ.get("SLIPSTREAM_ROS_NAMESPACE", "/").rstrip("/")
    cmd = ROS2Publisher(f"{under}/vehicle/ackermann_cmd", "ackermann_msgs/msg/AckermannDriveStamped",
                        node_name="my_acc")
    Header = cmd.session_mgr.store.types["std_msgs/msg/Header"]
    Time = cmd.session_mgr.store.types["builtin_interfaces/msg/Time"]
    Drive = cmd.session_mgr.store.types["ackermann_msgs/msg/AckermannDrive"]

    def on_odometry(odom):
        stamp = odom.header.stamp if args.stamp == "odometry" else Time(sec=0, nanosec=0)
        drive = Drive(steering_angle=0.0, steering_angle_velocity=0.0, speed=args.speed, acceleration=0.0, jerk=0.0)
        cmd.publish(header=Header(stamp=stamp, frame_id="ego"), drive=drive)
        answered[0] += 1

    # Listening last: the bridge joins the loop once both endpoints are in the ROS graph.
    odom = ROS2Subscriber(f"{under}/vehicle/odometry", "nav_msgs/msg/Odometry", on_odometry, node_name="my_acc")
    print(f"my_acc: listening on {dial}", file=sys.stderr, flush=True)
    done.wait()
    odom.close()
    cmd.close()
    print(f"my_acc: {answered[0]} odometry messages answered", flush=True)


if __name__ == "__main__":
    sys.exit(main())
