"""The seed design's speed link, as a bench peer: Python, standard library only, the speed as
text in one UDP datagram per message (the seed sends str(speed).encode() to a fixed port; here
the text also carries a sequence number and the send time, so that loss and one-way latency
can be counted the way the other bench paths count them).

Run by `slipstream bench` (written next to the run from the binary), never by hand:
  python3 seed_udp.py recv --spec JSON            prints READY host:port, on "stop" RESULT {...}
  python3 seed_udp.py send --spec JSON --endpoint host:port     prints SENT {...}
"""

import json
import socket
import sys
import threading
import time


def arg(name):
    return sys.argv[sys.argv.index(name) + 1]


def receive(spec):
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    sock.settimeout(0.05)
    got = {"received": 0, "bytes": 0, "highest": None, "lat": [], "first": None, "last": None}
    stop = threading.Event()

    def loop():
        while not stop.is_set():
            try:
                data = sock.recv(2048)
            except socket.timeout:
                continue
            now_ns, now = time.time_ns(), time.monotonic()
            seq, stamp, speed = data.decode().split()
            float(speed)  # what the seed's receiver does with it
            seq = int(seq)
            got["lat"].append(now_ns - int(stamp))
            got["received"] += 1
            got["bytes"] += len(data)
            got["highest"] = seq if got["highest"] is None else max(got["highest"], seq)
            got["first"] = got["first"] or now
            got["last"] = now

    t = threading.Thread(target=loop, daemon=True)
    t.start()
    host, port = sock.getsockname()
    print(f"READY {host}:{port}", flush=True)
    for line in sys.stdin:
        if line.strip() == "stop":
            break
    stop.set()
    t.join()
    span = (got["last"] - got["first"]) if got["first"] is not None else 0.0
    report = {"received": got["received"], "highest_seq": got["highest"], "bytes": got["bytes"],
              "latencies_ns": got["lat"], "span_s": span, "background_received": 0, "shared_memory": 0}
    print("RESULT " + json.dumps(report), flush=True)


def send(spec, endpoint):
    host, port = endpoint.rsplit(":", 1)
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    address = (host, int(port))
    period = 1.0 / spec["rate_hz"] if spec.get("rate_hz") else 0.0
    start = time.monotonic()
    deadline = start + spec["max_duration_s"]
    sent = 0
    for i in range(spec["count"]):
        if time.monotonic() > deadline:
            break
        due = start + i * period
        delay = due - time.monotonic()
        if delay > 0:
            time.sleep(delay)
        speed = 27.5 + (i % 10) * 0.1
        sock.sendto(f"{i} {time.time_ns()} {speed}".encode(), address)
        sent += 1
    elapsed = time.monotonic() - start
    time.sleep(0.3)  # the last datagram's time to arrive, as the other senders allow
    print("SENT " + json.dumps({"sent": sent, "elapsed_s": elapsed, "background_sent": 0}), flush=True)


def main():
    role, spec = sys.argv[1], json.loads(arg("--spec"))
    if role == "recv":
        receive(spec)
    else:
        send(spec, arg("--endpoint"))


if __name__ == "__main__":
    main()
