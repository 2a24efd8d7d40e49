#!/usr/bin/env python3
"""The Foxglove path in a real viewer: Lichtblick (the open-source fork of the Foxglove app,
MPL-2.0), built from its source, shows slipstream's live view and its recordings; headless
Chromium takes the screenshots docs/viewing.md shows.

    scripts/lichtblick-view.sh                 # builds Lichtblick if needed, then runs this
    .venv/bin/python scripts/lichtblick_view.py --lichtblick DIR/web/.webpack --out docs/images

Opt-in (not in the README's test command: building Lichtblick takes minutes and 1.5 GB of npm
packages). What it does:
  1. serves Lichtblick's built web app and the recordings over HTTP on loopback;
  2. `slipstream up --view --record --viewable --ros2` on cut-in, in real time;
  3. opens Lichtblick on `ds=foxglove-websocket` at the view's port, imports
     config/foxglove-layout.json through the app's own "Import layout from file" (the file
     picker answered with the file), waits, and takes lichtblick-live.png;
  4. opens the run's run.mcap (the --viewable copies) and run.ros2.mcap (profile ros2) with
     `ds=remote-file`, and takes lichtblick-recording.png and lichtblick-ros2.png.
Exit 1 when a step fails, with the step; the browser's console errors are printed."""

import argparse
import functools
import json
import http.server
import pathlib
import signal
import socket
import subprocess
import sys
import threading
import time

from selenium import webdriver
from selenium.webdriver.common.action_chains import ActionChains
from selenium.webdriver.common.by import By

ROOT = pathlib.Path(__file__).resolve().parents[1]
LAYOUT = ROOT / "config" / "foxglove-layout.json"
NAMESPACE = "lichtblick"


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Files(http.server.SimpleHTTPRequestHandler):
    """Static files with what a browser app reading a remote file needs: byte ranges (MCAP
    readers seek) and CORS (the app is served from another port)."""

    def log_message(self, *args):
        pass

    def end_headers(self):
        self.send_header("Access-Control-Allow-Origin", "*")
        self.send_header("Access-Control-Allow-Headers", "Range")
        self.send_header("Access-Control-Expose-Headers", "Content-Length, Content-Range, Accept-Ranges")
        self.send_header("Accept-Ranges", "bytes")
        super().end_headers()

    def do_OPTIONS(self):
        self.send_response(204)
        self.end_headers()

    def do_GET(self):
        wanted = self.headers.get("Range", "")
        path = pathlib.Path(self.translate_path(self.path))
        if not wanted.startswith("bytes=") or not path.is_file():
            return super().do_GET()
        size = path.stat().st_size
        first, _, last = wanted[6:].split(",")[0].partition("-")
        start = int(first) if first else max(0, size - int(last))
        end = min(int(last), size - 1) if first and last else size - 1
        self.send_response(206)
        self.send_header("Content-Type", "application/octet-stream")
        self.send_header("Content-Range", f"bytes {start}-{end}/{size}")
        self.send_header("Content-Length", str(end - start + 1))
        self.end_headers()
        with path.open("rb") as f:
            f.seek(start)
            left = end - start + 1
            while left > 0:
                chunk = f.read(min(left, 1 << 20))
                if not chunk:
                    break
                self.wfile.write(chunk)
                left -= len(chunk)


def serve(directory, port):
    """A static file server for `directory` on loopback, in a thread."""
    handler = functools.partial(Files, directory=str(directory))
    server = http.server.ThreadingHTTPServer(("127.0.0.1", port), handler)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    return server


def chrome(width, height):
    opts = webdriver.ChromeOptions()
    opts.binary_location = "/usr/bin/chromium"
    for arg in ("--headless=new", "--no-sandbox", "--disable-dev-shm-usage", "--use-angle=swiftshader",
                "--enable-unsafe-swiftshader", f"--window-size={width},{height}", "--force-device-scale-factor=1"):
        opts.add_argument(arg)
    opts.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    return webdriver.Chrome(options=opts, service=webdriver.ChromeService(executable_path="/usr/bin/chromedriver"))


def ros2_layout(namespace):
    """config/foxglove-layout.json for a `--profile ros2` recording: the same panels on the ROS 2
    topics (docs/ros2.md): image_raw and camera_info, the ground truth's and the detector's
    markers, the odometry's speed, the ACC's status by index (set speed 1, gap 5, desired gap 6,
    target acceleration 3)."""
    layout = json.loads(LAYOUT.read_text())
    ns = f"/{namespace}"
    panels = layout["configById"]
    panels["Image!camera"]["imageMode"].update(
        imageTopic=f"{ns}/camera/front/image_raw", calibrationTopic=f"{ns}/camera/front/camera_info", annotations={})
    panels["3D!scene"].update(followTf=f"{namespace}/ego", topics={
        f"{ns}/objects/markers": {"visible": True}, f"{ns}/perception/markers": {"visible": True}})
    panels["3D!scene"]["layers"]["grid"]["frameId"] = f"{namespace}/ego"
    status = f"{ns}/acc/status.data"
    for panel, paths in (("Plot!speed", [f"{ns}/vehicle/odometry.twist.twist.linear.x", f"{status}[1]"]),
                         ("Plot!gap", [f"{status}[5]", f"{status}[6]"]), ("Plot!accel", [f"{status}[3]"])):
        panels[panel]["paths"] = [{"value": v, "enabled": True, "timestampMethod": "receiveTime"} for v in paths]
    panels["RawMessages!acc"]["topicPath"] = f"{ns}/acc/status"
    return json.dumps(layout)


def import_layout(driver, text):
    """The app's own Layouts tab > Import layout, its file picker answered with `text`."""
    driver.execute_script(
        "const text = arguments[0];"
        "window.showOpenFilePicker = async () => [{getFile: async () => "
        "new File([text], 'foxglove-layout.json', {type: 'application/json'})}];", text)
    tabs = driver.find_elements(By.XPATH, "//*[@role='tab' and normalize-space()='Layouts']")
    if not tabs:
        raise SystemExit("step: import the layout: no Layouts tab in the left sidebar")
    tabs[0].click()
    time.sleep(0.5)
    buttons = driver.find_elements(By.CSS_SELECTOR, "[aria-label='Import layout']") or driver.find_elements(
        By.XPATH, "//*[self::li or self::button or @role='button'][starts-with(normalize-space(), 'Import from file')]")
    if not buttons:
        raise SystemExit("step: import the layout: no 'Import layout' or 'Import from file' in the Layouts tab")
    buttons[0].click()
    time.sleep(1)


def shoot(driver, url, out, wait_s, play=False, layout=None):
    """Opens `url`, imports the layout, plays a recording for `wait_s` (or watches the live
    view that long), and saves the screenshot; prints the console's errors."""
    driver.get(url)
    time.sleep(5)
    import_layout(driver, layout or LAYOUT.read_text())
    if play:
        buttons = driver.find_elements(By.CSS_SELECTOR, "[title=Play]")
        if not buttons:
            raise SystemExit(f"step: play {url}: no Play button")
        buttons[0].click()
    time.sleep(wait_s)
    if play:
        driver.find_element(By.CSS_SELECTOR, "[title=Pause]").click()
        time.sleep(1)
    driver.save_screenshot(str(out))
    print(f"{out}: {url}")
    for e in driver.get_log("browser"):
        if e["level"] == "SEVERE":
            print("  console:", e["message"][:300])


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--lichtblick", required=True, type=pathlib.Path, help="Lichtblick's built web app (web/.webpack)")
    parser.add_argument("--out", type=pathlib.Path, default=ROOT / "target" / "lichtblick")
    parser.add_argument("--slipstream", default=str(ROOT / "target" / "release" / "slipstream"))
    parser.add_argument("--seconds", type=float, default=25, help="how long the live view is watched before the shot")
    args = parser.parse_args()
    if not (args.lichtblick / "index.html").is_file():
        raise SystemExit(f"step: serve Lichtblick: no index.html in {args.lichtblick} (build it: scripts/lichtblick-view.sh)")
    args.out.mkdir(parents=True, exist_ok=True)
    report = args.out / "run"
    app_port, view_port, zenoh_port = free_port(), free_port(), free_port()
    app = serve(args.lichtblick, app_port)
    files = None
    up = subprocess.Popen(
        [args.slipstream, "-n", NAMESPACE, "-l", f"tcp/127.0.0.1:{zenoh_port}", "up", "--scenario", "cut-in",
         "--duration", "60", "--view", "--view-port", str(view_port), "--record", "--viewable", "--ros2",
         "--report", str(report), "--plain"], cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    driver = chrome(1600, 1000)
    try:
        time.sleep(3)
        live = f"http://127.0.0.1:{app_port}/?ds=foxglove-websocket&ds.url=ws://127.0.0.1:{view_port}"
        shoot(driver, live, args.out / "lichtblick-live.png", args.seconds)
        up.send_signal(signal.SIGINT)
        up.communicate(timeout=120)
        files = serve(report, free_port())
        base = f"http://127.0.0.1:{files.server_address[1]}"
        for name, shot, layout in (("run.mcap", "lichtblick-recording.png", None),
                                   ("run.ros2.mcap", "lichtblick-ros2.png", ros2_layout(NAMESPACE))):
            if not (report / name).is_file():
                raise SystemExit(f"step: record: {report / name} was not written")
            url = f"http://127.0.0.1:{app_port}/?ds=remote-file&ds.url={base}/{name}"
            shoot(driver, url, args.out / shot, 12, play=True, layout=layout)
    finally:
        driver.quit()
        if up.poll() is None:
            up.send_signal(signal.SIGINT)
            up.wait(timeout=60)
        app.shutdown()
        if files:
            files.shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
