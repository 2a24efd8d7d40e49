#!/usr/bin/env python3
"""A minimal Foxglove WebSocket client of `slipstream view` / `up --view`: subscribes to every
channel advertised and prints, at the end, messages and megabytes received per topic.
Used by scripts/measure-view.sh; handy to check a view from a terminal. Needs `websockets`
(scripts/test.sh installs it in .venv).

  .venv/bin/python scripts/view_client.py --port 8765 --seconds 10
"""

import argparse
import json
import time

from websockets.exceptions import ConnectionClosed
from websockets.sync.client import connect


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--host", default="127.0.0.1")
    ap.add_argument("--port", type=int, default=8765)
    ap.add_argument("--seconds", type=float, default=10.0, help="how long to listen at most (it also ends when the view does)")
    ap.add_argument("--connect-timeout", type=float, default=60.0, help="how long to retry connecting")
    args = ap.parse_args()
    deadline = time.monotonic() + args.connect_timeout
    while True:
        try:
            ws = connect(f"ws://{args.host}:{args.port}", subprotocols=["foxglove.sdk.v1"], max_size=None)
            break
        except OSError:
            if time.monotonic() > deadline:
                raise
            time.sleep(0.2)
    topics, counts, sizes = {}, {}, {}
    end = time.monotonic() + args.seconds
    with ws:
        while (left := end - time.monotonic()) > 0:
            try:
                frame = ws.recv(timeout=left)
            except (TimeoutError, ConnectionClosed):
                break
            if isinstance(frame, str):
                msg = json.loads(frame)
                if msg.get("op") == "advertise":
                    subs = []
                    for ch in msg["channels"]:
                        sub = len(topics) + 1
                        topics[sub] = ch["topic"]
                        subs.append({"id": sub, "channelId": ch["id"]})
                    ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))
            elif frame[0] == 0x01:
                topic = topics[int.from_bytes(frame[1:5], "little")]
                counts[topic] = counts.get(topic, 0) + 1
                sizes[topic] = sizes.get(topic, 0) + len(frame) - 13
    listened = args.seconds - max(0.0, end - time.monotonic())
    print(f"listened {listened:.1f} s")
    for topic in sorted(topics.values()):
        n = counts.get(topic, 0)
        print(f"{topic:32} {n:6} messages {n / listened:7.1f}/s {sizes.get(topic, 0) / 1e6:8.1f} MB")


if __name__ == "__main__":
    main()
