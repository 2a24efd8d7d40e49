#!/usr/bin/env bash
# Figures for docs/performance.md ("Recording and playback"): what recording costs the loop,
# the file size per minute, the recorder's CPU, and playback speed against reading the file.
# Loopback only (the default config). Takes about 6 minutes. Needs a release build.
set -euo pipefail
cd "$(dirname "$0")/.."
bin=target/release/slipstream
out=${1:-target/measure-recording}
rm -rf "$out" && mkdir -p "$out"
# The simulator's own real-time factor (up's includes starting and stopping the nodes).
rtf() { python3 -c 'import json,sys; r=json.load(open(sys.argv[1])); print("%.2f" % r["real_time_factor"])' "$1/logs/slipstream-sim.json"; }

lost() { python3 -c 'import json,sys; r=json.load(open(sys.argv[1]))["recording"]; print(r["lost_upstream"], r["dropped_by_recorder"])' "$1/report.json"; }
echo "== fast mode, camera perception, cut-in for 200 s simulated: the simulator's real-time factor"
echo "   without recording / with --record / with --record --viewable (lost: sequence gaps, dropped by the recorder)"
for i in 1 2 3; do
  "$bin" up --mode fast --duration 200 --plain --report "$out/plain-$i" >/dev/null 2>&1 || true
  "$bin" up --mode fast --duration 200 --plain --record --report "$out/rec-$i" >/dev/null 2>&1 || true
  "$bin" up --mode fast --duration 200 --plain --record --viewable --report "$out/viewable-$i" >/dev/null 2>&1 || true
  echo "run $i: without $(rtf "$out/plain-$i")  with $(rtf "$out/rec-$i") (lost $(lost "$out/rec-$i"))  viewable $(rtf "$out/viewable-$i") (lost $(lost "$out/viewable-$i"))"
done
ls -l "$out/rec-1/run.mcap" "$out/viewable-1/run.mcap" | awk '{printf "%s: %.1f MB\n", $9, $5/1e6}'

echo "== realtime, 60 s: a separate recorder's file size and CPU (then the same with --viewable)"
port=$(python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])')
"$bin" -l "tcp/127.0.0.1:$port" up --duration 60 --plain --report "$out/realtime" >/dev/null 2>&1 &
up=$!
sleep 2
/usr/bin/env time -f "recorder: %U s user %S s system, max RSS %M kB, %e s wall" \
  "$bin" -e "tcp/127.0.0.1:$port" record -o "$out/realtime.mcap" --duration 55 2>&1 | tail -16
wait $up || true
ls -l "$out/realtime.mcap" | awk '{printf "file: %.1f MB for 55 s = %.1f MB per minute\n", $5/1e6, $5/1e6*60/55}'
port=$(python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])')
"$bin" -l "tcp/127.0.0.1:$port" up --duration 60 --plain --report "$out/realtime-v" >/dev/null 2>&1 &
up=$!
sleep 2
/usr/bin/env time -f "recorder --viewable: %U s user %S s system, max RSS %M kB, %e s wall" \
  "$bin" -e "tcp/127.0.0.1:$port" record --viewable --scenario cut-in -o "$out/realtime-v.mcap" --duration 55 2>&1 | tail -3
wait $up || true
ls -l "$out/realtime-v.mcap" | awk '{printf "file with --viewable: %.1f MB for 55 s = %.1f MB per minute\n", $5/1e6, $5/1e6*60/55}'

echo "== playback: --max into a recorder (file -> bus -> file) vs reading the file alone"
port2=$(python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])')
"$bin" -l "tcp/127.0.0.1:$port2" record -o "$out/replayed.mcap" --duration 60 > "$out/replayed.txt" 2>&1 &
rec=$!
sleep 2
/usr/bin/env time -f "play --max: %e s wall, %U s user" "$bin" -e "tcp/127.0.0.1:$port2" play --max "$out/rec-1/run.mcap" 2>&1 | tail -2
sleep 1
kill -INT $rec; wait $rec || true
grep -E "^recording|LOST|nothing lost" "$out/replayed.txt"
py=.venv/bin/python; [ -x "$py" ] || py=python3
"$py" - "$out/rec-1/run.mcap" <<'PY' || echo "(the python mcap package is missing: scripts/test.sh installs it in .venv)"
import sys, time
from mcap.reader import make_reader
t = time.time(); n = b = 0
with open(sys.argv[1], "rb") as f:
    for _, _, m in make_reader(f).iter_messages():
        n += 1; b += len(m.data)
d = time.time() - t
print(f"reading alone (python mcap): {n} messages, {b/1e6:.0f} MB in {d:.2f} s = {n/d:.0f} msg/s, {b/1e6/d:.0f} MB/s")
PY
