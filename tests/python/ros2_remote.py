"""A ROS 2 side on another host: lists the graph through the router as `ros2 topic list -t` does
(zenoh-ros2-sdk, from the liveliness tokens), then takes /clock and the odometry through the router
and decodes them with rosbags. Prints one JSON object. Usage: ros2_remote.py ROUTER_IP PORT SECONDS"""

import json
import sys
import time

import zenoh
from rosbags.typesys import Stores, get_typestore
from zenoh_ros2_sdk import discovery


def main():
    router_ip, port, seconds = sys.argv[1], int(sys.argv[2]), float(sys.argv[3])
    deadline = time.time() + seconds
    topics = {}
    while time.time() < deadline and "/clock" not in topics:
        topics = dict(discovery.get_topic_names_and_types(domain_id=0, router_ip=router_ip, router_port=port,
                                                          timeout=1.0))
    ts = get_typestore(Stores.ROS2_JAZZY)
    got = {"clock": [], "odometry": []}
    conf = zenoh.Config()
    conf.insert_json5("mode", '"client"')
    conf.insert_json5("connect/endpoints", json.dumps([f"tcp/{router_ip}:{port}"]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    with zenoh.open(conf) as session:
        subs = [
            session.declare_subscriber("0/clock/**", lambda s: got["clock"].append(
                ts.deserialize_cdr(s.payload.to_bytes(), "rosgraph_msgs/msg/Clock").clock.sec)),
            session.declare_subscriber("0/vehicle/odometry/**", lambda s: got["odometry"].append(
                ts.deserialize_cdr(s.payload.to_bytes(), "nav_msgs/msg/Odometry").twist.twist.linear.x)),
        ]
        while time.time() < deadline and min(len(v) for v in got.values()) < 50:
            time.sleep(0.1)
        for s in subs:
            s.undeclare()
    print(json.dumps({"topics": topics, "clock": len(got["clock"]), "odometry": len(got["odometry"]),
                      "speed": got["odometry"][-1] if got["odometry"] else None}))


if __name__ == "__main__":
    main()
