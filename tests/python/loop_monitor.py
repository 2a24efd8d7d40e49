"""A node in no role of ours, for tests/python/test_loop_file.py: it publishes a heartbeat on
monitor/heartbeat under the run's namespace (its readiness, as its loop file says) and counts the
acc/status samples it sees; prints the count when stopped."""

import os
import signal
import time

import zenoh

from slipstream_client import Topics

stop = []
signal.signal(signal.SIGINT, lambda *_: stop.append(1))
signal.signal(signal.SIGTERM, lambda *_: stop.append(1))
topics = Topics.load()
namespace = os.environ.get("SLIPSTREAM_NAMESPACE", "")
heartbeat = f"{namespace}/monitor/heartbeat" if namespace else "monitor/heartbeat"
seen = []
with zenoh.open(zenoh.Config.from_file(os.environ["SLIPSTREAM_ZENOH_CONFIG"])) as session:
    sub = session.declare_subscriber(topics.key("acc/status"), lambda _s: seen.append(1))
    pub = session.declare_publisher(heartbeat)
    while not stop:
        pub.put(b"alive")
        time.sleep(0.1)
print(f"monitor: {len(seen)} acc/status samples", flush=True)
