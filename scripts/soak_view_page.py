#!/usr/bin/env python3
"""A page left open, and bad input at the view's port, beside a recording loop: does anything
grow or suffer? Two phases of `slipstream up --view --record` in real time on cut-in, each with
a headless Chromium page open the whole time; in the second, a thrower also sends the port
what it should refuse, every second: a path that is not there, bytes that are not HTTP, a
frame request closed mid-answer, a WebSocket whose messages are not the protocol, a second
page's requests cut off. Per phase: the `up` process's resident memory (sampled every 10 s),
the page's JavaScript heap, the loop's frame -> applied p50/p99 and what the recorder lost or
dropped (up's report), and the bad requests the view counted. Loopback only.

    .venv/bin/python scripts/soak_view_page.py [--minutes 20] [--bad-only] [--out DIR]

Needs a release build, .venv with selenium and websockets, chromium and chromium-driver."""

import argparse
import json
import pathlib
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


def rss_mb(pid):
    for line in pathlib.Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    return float("nan")


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


def phase(binary, minutes, report, bad):
    port = free_port()
    up = subprocess.Popen(
        [binary, "-n", f"viewsoak-{int(bad)}", "-l", f"tcp/127.0.0.1:{free_port()}", "up", "--scenario", "cut-in",
         "--duration", str(minutes * 60), "--view", "--view-port", str(port), "--record", "--report", str(report),
         "--plain"], cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    time.sleep(5)
    driver = browser()
    driver.get(f"http://127.0.0.1:{port}/")
    stop, counts = threading.Event(), {}
    thrower = threading.Thread(target=throw_bad_input, args=(port, stop, counts), daemon=True)
    if bad:
        thrower.start()
    samples = []
    end = time.monotonic() + minutes * 60 - 15
    while time.monotonic() < end and up.poll() is None:
        heap = driver.execute_script("return performance.memory ? performance.memory.usedJSHeapSize : null")
        samples.append((time.monotonic(), rss_mb(up.pid), (heap or 0) / 2**20,
                        driver.execute_script("return window.slipstream.updates")))
        time.sleep(10)
    stop.set()
    driver.quit()
    _, err = up.communicate(timeout=180)
    r = json.loads((report / "report.json").read_text())
    hop = next(h for h in r["latency"]["hops"] if h["hop"] == "frame -> applied")
    rec = r.get("recording") or {}
    return samples, hop, rec, r["view"]["page"], counts, err


def summary(name, samples, hop, rec, page, counts):
    minute = 6  # samples per minute
    first, last = samples[:minute], samples[-minute:]
    rss0, rss1 = statistics.median(s[1] for s in first), statistics.median(s[1] for s in last)
    heap0, heap1 = statistics.median(s[2] for s in first), statistics.median(s[2] for s in last)
    rate = (samples[-1][3] - samples[0][3]) / (samples[-1][0] - samples[0][0])
    lost, dropped = rec.get("lost_upstream", "?"), rec.get("dropped_by_recorder", "?")
    print(f"{name}: up's RSS {rss0:.0f} -> {rss1:.0f} MB (first and last minute), page heap {heap0:.1f} -> "
          f"{heap1:.1f} MB, page {rate:.1f} updates/s; frame -> applied p50 {hop['p50_ms']:.2f} ms, p99 "
          f"{hop['p99_ms']:.2f} ms; recorder lost {lost}, dropped {dropped}; view counted {page['bad_requests']} "
          f"bad requests, thrown {sum(counts.values())} ({counts})", flush=True)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--minutes", type=int, default=20, help="length of each phase")
    parser.add_argument("--out", type=pathlib.Path, default=ROOT / "target" / "soak-view-page")
    parser.add_argument("--slipstream", default=str(ROOT / "target" / "release" / "slipstream"))
    parser.add_argument("--bad-only", action="store_true", help="only the phase with bad input")
    args = parser.parse_args()
    for bad in (True,) if args.bad_only else (False, True):
        name = "page + bad input" if bad else "page alone"
        report = args.out / ("bad" if bad else "page")
        samples, hop, rec, page, counts, err = phase(args.slipstream, args.minutes, report, bad)
        summary(name, samples, hop, rec, page, counts)
        (args.out / f"{'bad' if bad else 'page'}-rss.csv").write_text(
            "t_s,rss_mb,page_heap_mb,page_updates\n" +
            "".join(f"{t - samples[0][0]:.0f},{r:.1f},{h:.2f},{u}\n" for t, r, h, u in samples))
        warnings = [line for line in err.splitlines() if "view:" in line]
        print(f"  the view's warnings: {len(warnings)}", *warnings[:3], sep="\n    ")


if __name__ == "__main__":
    main()
