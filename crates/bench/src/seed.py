"""The seed design's links, as bench peers: Python, standard library only.

- speed (transport "seed-python-udp"): the speed as text in one UDP datagram per message (the
  seed sends str(speed).encode() to a fixed port);
- camera (transport "seed-python-tcp-pickle"): each frame pickled and sent over one TCP
  connection behind a 4-byte big-endian length (struct '>I'), received 4096 bytes at a time
  and appended to a bytes buffer, then unpickled, as the seed's image port does. The seed
  pickles the numpy array its camera returns; here the pixels are a bytes object of the same
  size (no numpy on a fresh machine), which pickles and unpickles as one copy, as the array does.

The messages also carry a sequence number and the send time, so that loss and one-way latency
are counted the way the other bench paths count them.

Run by `slipstream bench` (written next to the run from the binary), never by hand:
  python3 seed.py recv --spec JSON                          prints READY host:port, on "stop" RESULT {...}
  python3 seed.py send --spec JSON --endpoint host:port     prints SENT {...}
"""

import json
import pickle
import socket
import struct
import sys
import threading
import time


def arg(name):
    return sys.argv[sys.argv.index(name) + 1]


class Collected:
    """What a receiver counts, in the bench's report format."""

    def __init__(self):
        self.received, self.bytes, self.highest, self.lat = 0, 0, None, []
        self.first = self.last = None

    def record(self, seq, stamp_ns, size):
        now_ns = time.time_ns()
        self.lat.append(now_ns - stamp_ns)
        self.received += 1
        self.bytes += size
        self.highest = seq if self.highest is None else max(self.highest, seq)
        # The span: from the first message's publication to the last one's arrival (the
        # Rust receiver's definition, crates/bench/src/spec.rs RecvReport.span_s).
        self.first = stamp_ns if self.first is None else min(self.first, stamp_ns)
        self.last = now_ns

    def report(self):
        span = (self.last - self.first) / 1e9 if self.first is not None else 0.0
        return {"received": self.received, "highest_seq": self.highest, "bytes": self.bytes,
                "latencies_ns": self.lat, "span_s": span, "background_received": 0, "shared_memory": 0}


def receive_udp(got, stop):
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    sock.settimeout(0.05)

    def loop():
        while not stop.is_set():
            try:
                data = sock.recv(2048)
            except socket.timeout:
                continue
            seq, stamp, speed = data.decode().split()
            float(speed)  # what the seed's receiver does with it
            got.record(int(seq), int(stamp), len(data))

    return sock.getsockname(), loop


def receive_tcp_pickle(got, stop):
    listener = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    listener.bind(("127.0.0.1", 0))
    listener.listen(1)
    listener.settimeout(0.05)
    header = struct.calcsize(">I")

    def fill(conn, data, size):
        # The seed's receive loop: 4096 bytes at a time, appended to the buffer.
        while len(data) < size and not stop.is_set():
            try:
                packet = conn.recv(4096)
            except socket.timeout:
                continue
            if not packet:
                return None
            data += packet
        return data if len(data) >= size else None

    def loop():
        conn = None
        while conn is None and not stop.is_set():
            try:
                conn, _ = listener.accept()
            except socket.timeout:
                continue
        if conn is None:
            return
        conn.settimeout(0.05)
        data = b""
        while not stop.is_set():
            data = fill(conn, data, header)
            if data is None:
                return
            size = struct.unpack(">I", data[:header])[0]
            data = fill(conn, data[header:], size)
            if data is None:
                return
            seq, stamp, pixels = pickle.loads(data[:size])
            data = data[size:]
            got.record(seq, stamp, len(pixels))

    return listener.getsockname(), loop


def receive(spec):
    got, stop = Collected(), threading.Event()
    make = receive_tcp_pickle if spec["transport"] == "seed-python-tcp-pickle" else receive_udp
    (host, port), loop = make(got, stop)
    t = threading.Thread(target=loop, daemon=True)
    t.start()
    print(f"READY {host}:{port}", flush=True)
    for line in sys.stdin:
        if line.strip() == "stop":
            break
    stop.set()
    t.join()
    print("RESULT " + json.dumps(got.report()), flush=True)


def paced(spec, send_one):
    """Calls send_one(i) at the spec's rate (or at once), until its count or its time is up."""
    period = 1.0 / spec["rate_hz"] if spec.get("rate_hz") else 0.0
    start = time.monotonic()
    deadline = start + spec["max_duration_s"]
    sent = 0
    for i in range(spec["count"]):
        if time.monotonic() > deadline:
            break
        delay = start + i * period - time.monotonic()
        if delay > 0:
            time.sleep(delay)
        send_one(i)
        sent += 1
    return sent, time.monotonic() - start


def send_udp(spec, host, port):
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    address = (host, port)

    def one(i):
        speed = 27.5 + (i % 10) * 0.1
        sock.sendto(f"{i} {time.time_ns()} {speed}".encode(), address)

    return paced(spec, one)


def send_tcp_pickle(spec, host, port):
    frame = spec["payload"]["frame"]
    pixels = bytes(frame["width"] * frame["height"] * 3)
    conn = socket.create_connection((host, port))

    def one(i):
        serialized = pickle.dumps((i, time.time_ns(), pixels))
        conn.sendall(struct.pack(">I", len(serialized)) + serialized)

    result = paced(spec, one)
    return result


def send(spec, endpoint):
    host, port = endpoint.rsplit(":", 1)
    if spec["transport"] == "seed-python-tcp-pickle":
        sent, elapsed = send_tcp_pickle(spec, host, int(port))
    else:
        sent, elapsed = send_udp(spec, host, int(port))
    time.sleep(0.3)  # the last message's time to arrive, as the other senders allow
    print("SENT " + json.dumps({"sent": sent, "elapsed_s": elapsed, "background_sent": 0}), flush=True)


def main():
    role, spec = sys.argv[1], json.loads(arg("--spec"))
    if role == "recv":
        receive(spec)
    else:
        send(spec, arg("--endpoint"))


if __name__ == "__main__":
    main()
