#!/usr/bin/env bash
# Figures for docs/performance.md ("Live view"): what `up --view` costs the loop, with no
# viewer and with a viewer subscribed to every channel (scripts/view_client.py), in fast mode
# where the loop keeps both cores busy. Loopback only. About 2 minutes. Needs a release build
# and .venv with websockets (scripts/test.sh).
set -euo pipefail
cd "$(dirname "$0")/.."
bin=target/release/slipstream
py=.venv/bin/python
out=${1:-target/measure-view}
rm -rf "$out" && mkdir -p "$out"
rtf() { python3 -c 'import json,sys; r=json.load(open(sys.argv[1])); print("%.2f" % r["real_time_factor"])' "$1/logs/slipstream-sim.json"; }
free_port() { python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])'; }

echo "== fast mode, camera perception, cut-in for 200 s simulated: the simulator's real-time factor"
echo "   without the view / with --view and no viewer / with --view and a viewer of every channel"
for i in 1 2 3; do
  "$bin" up --mode fast --duration 200 --plain --report "$out/plain-$i" >/dev/null 2>&1 || true
  p=$(free_port)
  "$bin" up --mode fast --duration 200 --plain --view --view-port "$p" --report "$out/view-$i" >/dev/null 2>&1 || true
  p=$(free_port)
  "$bin" up --mode fast --duration 200 --plain --view --view-port "$p" --report "$out/viewer-$i" >/dev/null 2>"$out/viewer-$i.err" &
  up=$!
  "$py" scripts/view_client.py --port "$p" --seconds 600 --connect-timeout 30 > "$out/viewer-$i.txt" 2>&1 &
  client=$!
  wait $up || true
  wait $client || true
  echo "run $i: without $(rtf "$out/plain-$i")  view $(rtf "$out/view-$i")  view+viewer $(rtf "$out/viewer-$i")  ($(python3 -c 'import json,sys; v=json.load(open(sys.argv[1]))["view"]; print(v["images"], "images", v["annotations"], "annotations sent")' "$out/viewer-$i/report.json"))"
done
