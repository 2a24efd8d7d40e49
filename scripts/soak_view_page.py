#!/usr/bin/env python3
"""A page left open, and bad input at the view's port, beside a recording loop: does anything
grow or suffer? Two phases of `slipstream up --record` in real time on cut-in with
`slipstream view` beside it as a process of its own (the same view `up --view` runs, in a
process whose memory is the view's alone: `up` keeps its run's trace to judge it, and that
grows with the run), each with a headless Chromium page open the whole time; in the second, a
thrower also sends the port what it should refuse, every second: a path that is not there,
bytes that are not HTTP, a frame request closed mid-answer, a request head cut off, a
WebSocket whose messages are not the protocol. Per phase: the view's and `up`'s resident
own memory (RssAnon, sampled every 10 s; the shared-memory segments a process maps count
into its resident size but are the simulator's), the page's JavaScript heap and update rate, the loop's frame ->
applied p50/p99 and what the recorder lost or dropped (up's report), and what the view
counted. Loopback only.

    .venv/bin/python scripts/soak_view_page.py [--minutes 60] [--bad-minutes 15] [--bad-only] [--out DIR]

Needs a release build, .venv with selenium and websockets, chromium and chromium-driver."""

import argparse
import json
import os
import pathlib
import signal
import socket
import statistics
import subprocess
import threading
import time
import urllib.request

from selenium import webdriver
from websockets.sync.client import connect as ws_connect

ROOT = pathlib.Path(__file__).resolve().parents[1]


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def browser():
    opts = webdriver.ChromeOptions()
    opts.binary_location = "/usr/bin/chromium"
    for arg in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage",
                "--window-size=1400,1000", "--enable-precise-memory-info"):
        opts.add_argument(arg)
    return webdriver.Chrome(options=opts, service=webdriver.ChromeService(executable_path="/usr/bin/chromedriver"))


def private_mb(pid):
    """A process's own memory (RssAnon) and the shared memory it has mapped (RssShmem), MB.
    Zenoh's shared-memory segments, which the simulator's frames arrive in, count into a
    subscriber's resident size as it maps them; they are the publisher's pages, not its own."""
    fields = dict(line.split(":", 1) for line in pathlib.Path(f"/proc/{pid}/status").read_text().splitlines())
    kb = lambda key: int(fields.get(key, "0 kB").split()[0]) / 1024  # noqa: E731
    return kb("RssAnon"), kb("RssShmem")


def throw_bad_input(port, stop, counts):
    """Every second, one of each kind of bad input, until `stop` is set."""
    while not stop.is_set():
        for name, act in (("404", lambda: urllib.request.urlopen(f"http://127.0.0.1:{port}/no/such", timeout=5)),
                          ("not http", lambda: raw(port, b"\x16\x03\x01\x02\x00 hello\r\n\r\n", 64)),
                          ("cut frame", lambda: raw(port, b"GET /frame?w=640 HTTP/1.1\r\n\r\n", 100)),
                          ("cut head", lambda: raw(port, b"GET /state HTTP/1.1\r\nHo", 0)),
                          ("ws garbage", lambda: ws_garbage(port))):
            try:
                act()
            except Exception:  # noqa: BLE001 - a refused request is the point
                pass
            counts[name] = counts.get(name, 0) + 1
        stop.wait(1.0)


def raw(port, data, read):
    with socket.create_connection(("127.0.0.1", port), timeout=5) as s:
        s.sendall(data)
        if read:
            s.recv(read)


def ws_garbage(port):
    with ws_connect(f"ws://127.0.0.1:{port}", subprotocols=["foxglove.sdk.v1"], open_timeout=5) as ws:
        ws.send("this is not the protocol")
        ws.send(b"\xff\x00garbage")
        ws.send('{"op": "subscribe", "subscriptions": "not a list"}')


def phase(binary, minutes, report, bad, csv):
    """One phase: the loop, the view beside it, a page open, bad input if `bad`; each sample
    goes to `csv` as it is taken (a phase cut short keeps what it measured)."""
    port, loop_port, ns = free_port(), free_port(), f"viewsoak-{os.getpid()}-{int(bad)}"
    seconds = minutes * 60
    up = subprocess.Popen(
        [binary, "-n", ns, "-l", f"tcp/127.0.0.1:{loop_port}", "up", "--scenario", "cut-in", "--duration",
         str(seconds), "--record", "--report", str(report), "--plain"],
        cwd=ROOT, stdout=subprocess.DEVNULL, stderr=(report.parent / f"up-{int(bad)}.log").open("w"))
    view = subprocess.Popen(
        [binary, "-n", ns, "-e", f"tcp/127.0.0.1:{loop_port}", "-l", f"tcp/127.0.0.1:{free_port()}", "view",
         "--view-port", str(port), "--duration", str(seconds + 60)],
        cwd=ROOT, stdout=subprocess.DEVNULL, stderr=(report.parent / f"view-{int(bad)}.log").open("w"))
    time.sleep(5)
    driver = browser()
    driver.get(f"http://127.0.0.1:{port}/")
    stop, counts = threading.Event(), {}
    thrower = threading.Thread(target=throw_bad_input, args=(port, stop, counts), daemon=True)
    if bad:
        thrower.start()
    samples = []
    csv.write_text("t_s,view_anon_mb,view_shmem_mb,up_anon_mb,page_heap_mb,page_updates\n")
    end = time.monotonic() + seconds - 15
    while time.monotonic() < end and up.poll() is None and view.poll() is None:
        heap = driver.execute_script("return performance.memory ? performance.memory.usedJSHeapSize : null")
        (view_anon, view_shmem), (up_anon, _) = private_mb(view.pid), private_mb(up.pid)
        samples.append((time.monotonic(), view_anon, up_anon, (heap or 0) / 2**20,
                        driver.execute_script("return window.slipstream.updates"), view_shmem))
        t, v, u, h, n, sh = samples[-1]
        with csv.open("a") as f:
            f.write(f"{t - samples[0][0]:.0f},{v:.1f},{sh:.1f},{u:.1f},{h:.2f},{n}\n")
        time.sleep(10)
    stop.set()
    counted = json.loads(urllib.request.urlopen(f"http://127.0.0.1:{port}/state", timeout=10).read())["view"]
    driver.quit()
    # A loaded machine runs the realtime loop a little slower than the wall clock: the loop is
    # stopped as a user stops it (its report is written on Ctrl-C) rather than awaited.
    up.send_signal(signal.SIGINT)
    up.wait(timeout=600)
    view.terminate()
    view.wait(timeout=60)
    err = (report.parent / f"view-{int(bad)}.log").read_text(errors="replace")
    r = json.loads((report / "report.json").read_text())
    hop = next(h for h in r["latency"]["hops"] if h["hop"] == "frame -> applied")
    return samples, hop, r.get("recording") or {}, counted, counts, err


def summary(name, samples, hop, rec, counted, counts):
    minute = 6  # samples per minute
    first, last = samples[:minute], samples[-minute:]
    med = lambda rows, k: statistics.median(s[k] for s in rows)  # noqa: E731
    rate = (samples[-1][4] - samples[0][4]) / (samples[-1][0] - samples[0][0])
    lost, dropped = rec.get("lost_upstream", "?"), rec.get("dropped_by_recorder", "?")
    print(f"{name}: the view's own memory (RssAnon) {med(first, 1):.1f} -> {med(last, 1):.1f} MB (medians of the "
          f"first and last minute, {(samples[-1][0] - samples[0][0]) / 60:.0f} minutes apart; max "
          f"{max(s[1] for s in samples):.1f}; shared segments mapped {med(last, 5):.0f} MB), "
          f"up's {med(first, 2):.0f} -> {med(last, 2):.0f} MB (its run's trace), page heap {med(first, 3):.1f} -> {med(last, 3):.1f} MB, "
          f"page {rate:.1f} updates/s; frame -> applied p50 {hop['p50_ms']:.2f} ms, p99 {hop['p99_ms']:.2f} ms; "
          f"recorder lost {lost}, dropped {dropped}; the view counted {counted['bad_requests']} bad requests, "
          f"{counted['refused']} refused, {counted['skipped']} frames skipped; thrown {sum(counts.values())} "
          f"({counts})", flush=True)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--minutes", type=int, default=60, help="length of the page-alone phase")
    parser.add_argument("--bad-minutes", type=int, default=15, help="length of the phase with bad input")
    parser.add_argument("--out", type=pathlib.Path, default=ROOT / "target" / "soak-view-page")
    parser.add_argument("--slipstream", default=str(ROOT / "target" / "release" / "slipstream"))
    parser.add_argument("--bad-only", action="store_true", help="only the phase with bad input")
    args = parser.parse_args()
    for bad in (True,) if args.bad_only else (False, True):
        name = "page + bad input" if bad else "page alone"
        report = args.out / ("bad" if bad else "page")
        minutes = args.bad_minutes if bad else args.minutes
        args.out.mkdir(parents=True, exist_ok=True)
        csv = args.out / f"{'bad' if bad else 'page'}-rss.csv"
        samples, hop, rec, counted, counts, err = phase(args.slipstream, minutes, report, bad, csv)
        summary(name, samples, hop, rec, counted, counts)
        warnings = [line for line in err.splitlines() if "view:" in line or "WARN" in line]
        print(f"  the view's log: {len(err)} bytes, {len(warnings)} warnings", *warnings[:3], sep="\n    ")


if __name__ == "__main__":
    main()
