#!/usr/bin/env python3
"""Figures for docs/performance.md ("The view's page"): what pages open in browsers cost the
loop. `slipstream up --view` in real time on cut-in with no browser, one and three headless
Chromium pages on the view (each a browser of its own: a background tab would be throttled),
runs interleaved; per run the loop's frame -> applied p50/p99 from up's report.json, and per
page its update rate (updates drawn per second) and the frames it skipped. Loopback only.
The browsers share this machine's cores with the loop; --nice runs them at the lowest
priority, and --pull replaces each with a Python loop asking for what a page asks for (the
view's own cost, as with browsers on other PCs).

    .venv/bin/python scripts/measure_view_page.py [--rounds 3] [--seconds 40] [--nice | --pull] [--out DIR]

About (rounds x 3 x seconds); needs a release build and .venv with selenium, and Debian's
chromium and chromium-driver (scripts/test.sh installs them)."""

import argparse
import json
import os
import pathlib
import socket
import statistics
import subprocess
import threading
import time

from selenium import webdriver

ROOT = pathlib.Path(__file__).resolve().parents[1]


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def browser(nice):
    """A headless Chromium; `nice`: at the lowest CPU priority, as a stand-in for a browser on
    another PC (what then remains is the view's own cost on this one)."""
    opts = webdriver.ChromeOptions()
    opts.binary_location = "/usr/bin/chromium"
    for arg in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage",
                "--window-size=1400,1000"):
        opts.add_argument(arg)
    popen = {"preexec_fn": lambda: os.nice(19)} if nice else {}
    service = webdriver.ChromeService(executable_path="/usr/bin/chromedriver", popen_kw=popen)
    return webdriver.Chrome(options=opts, service=service)


class Puller:
    """What a page asks for, without a browser: /state, then the frame it names at 640 px, in
    a loop as fast as the answers come, at most 20 a second. Its cost on this machine is the
    view's own (JSON, JPEG), without a browser's rendering."""

    def __init__(self, port):
        self.port, self.updates, self.stop = port, 0, False
        self.thread = threading.Thread(target=self.run, daemon=True)
        self.thread.start()

    def run(self):
        import urllib.request
        page = f"bench{id(self) % 10000}"
        while not self.stop:
            started = time.monotonic()
            with urllib.request.urlopen(f"http://127.0.0.1:{self.port}/state", timeout=10) as r:
                front = json.loads(r.read()).get("front")
            if front:
                url = f"http://127.0.0.1:{self.port}/frame?camera=front&stamp={front['stamp']}&w=640&page={page}"
                with urllib.request.urlopen(url, timeout=10) as r:
                    r.read()
            self.updates += 1
            time.sleep(max(0.0, 0.05 - (time.monotonic() - started)))

    def execute_script(self, _):
        return self.updates

    def quit(self):
        self.stop = True
        self.thread.join(timeout=10)


def wait_listening(port, proc, timeout=60):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline and proc.poll() is None:
        with socket.socket() as s:
            if s.connect_ex(("127.0.0.1", port)) == 0:
                return
        time.sleep(0.2)
    raise SystemExit(f"the view never listened on {port}")


def one_run(binary, pages, seconds, report, nice, pull):
    """One `up --view` of `seconds` with `pages` browsers on it: (hop figures, page rates)."""
    port = free_port()
    up = subprocess.Popen(
        [binary, "-n", f"viewbench-{pages}", "-l", f"tcp/127.0.0.1:{free_port()}", "up", "--scenario", "cut-in",
         "--duration", str(seconds), "--view", "--view-port", str(port), "--report", str(report), "--plain"],
        cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    drivers, rates = [], []
    try:
        wait_listening(port, up)
        for _ in range(pages):
            if pull:
                drivers.append(Puller(port))
                continue
            d = browser(nice)
            d.get(f"http://127.0.0.1:{port}/")
            drivers.append(d)
        time.sleep(5)
        start = [(time.monotonic(), d.execute_script("return window.slipstream.updates")) for d in drivers]
        time.sleep(max(5.0, seconds - 20))
        for d, (t0, n0) in zip(drivers, start):
            n1 = d.execute_script("return window.slipstream.updates")
            rates.append((n1 - n0) / (time.monotonic() - t0))
    finally:
        for d in drivers:
            d.quit()
        up.wait(timeout=seconds + 120)
    r = json.loads((report / "report.json").read_text())
    hop = next(h for h in r["latency"]["hops"] if h["hop"] == "frame -> applied")
    return hop, rates, r["view"]["page"]


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--seconds", type=int, default=40)
    parser.add_argument("--out", type=pathlib.Path, default=ROOT / "target" / "measure-view-page")
    parser.add_argument("--slipstream", default=str(ROOT / "target" / "release" / "slipstream"))
    parser.add_argument("--pull", action="store_true",
                        help="no browser: a Python loop asks for what a page asks for (the view's own cost)")
    parser.add_argument("--nice", action="store_true",
                        help="browsers at nice 19: the view's own cost, as with browsers on other PCs")
    args = parser.parse_args()
    results = {0: [], 1: [], 3: []}
    for k in range(args.rounds):
        for pages in results:
            hop, rates, served = one_run(args.slipstream, pages, args.seconds, args.out / f"{pages}-pages-{k}", args.nice, args.pull)
            results[pages].append((hop, rates, served))
            print(f"round {k + 1}, {pages} page(s): frame -> applied p50 {hop['p50_ms']:.2f} ms, p99 "
                  f"{hop['p99_ms']:.2f} ms ({hop['count']} loops); page updates/s "
                  f"{', '.join(f'{r:.1f}' for r in rates) or '-'}; served {served['frames']} frames, "
                  f"{served['skipped']} skipped", flush=True)
    base50 = statistics.median(h["p50_ms"] for h, _, _ in results[0])
    base99 = statistics.median(h["p99_ms"] for h, _, _ in results[0])
    print("\npages  frame->applied p50 ms (ratio)  p99 ms (ratio)  page updates/s (median)")
    for pages, runs in results.items():
        p50 = statistics.median(h["p50_ms"] for h, _, _ in runs)
        p99 = statistics.median(h["p99_ms"] for h, _, _ in runs)
        rates = [r for _, rs, _ in runs for r in rs]
        rate = f"{statistics.median(rates):.1f}" if rates else "-"
        print(f"{pages:>5}  {p50:8.2f} ({p50 / base50:.2f})            {p99:7.2f} ({p99 / base99:.2f})   {rate}")


if __name__ == "__main__":
    main()
