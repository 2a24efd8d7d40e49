#!/usr/bin/env bash
# Figures for docs/perception.md ("Noisy sensors"): detection through a noisy camera. Writes a
# scenario (a lead braking to a stop from 28 m/s, a van beside; seed 23) with 3, 6, 9 and 12
# levels of pixel noise per channel, and 12 with a brightness flicker of 0.25, then runs
# `slipstream eval detect` on the first 12 s of each (precision, recall within 60 m) and
# `slipstream eval acc` on the last. Lockstep, deterministic; under a minute. Needs a release
# build.
set -euo pipefail
cd "$(dirname "$0")/.."
bin=target/release/slipstream
out=${1:-target/measure-noisy-camera}
rm -rf "$out" && mkdir -p "$out"

scenario() { # name camera_stddev brightness
  cat >"$out/$1.json5" <<EOF
{
  name: "$1",
  description: "Camera noise $2 per channel, brightness flicker $3: the lead brakes to a stop.",
  duration_s: 35,
  seed: 23,
  ego: { lane: 1, speed_mps: 28, set_speed_mps: 30 },
  traffic: [
    { lane: 1, gap_m: 55, speed_mps: 28, actions: [ { at_s: 10, speed_mps: 0, accel_mps2: 5 } ] },
    { lane: 0, gap_m: 20, speed_mps: 26, class: "van" },
  ],
  noise: { camera_stddev: $2, brightness: $3, speed_mps: 0.1 },
  expect: { min_gap_m: 3 },
}
EOF
}
for n in 3 6 9 12; do scenario "noise-$n" "$n" 0; done
scenario noise-12-flicker 12 0.25

echo "== eval detect, 12 s: scenario | frames | precision | recall within 60 m"
for f in noise-3 noise-6 noise-9 noise-12 noise-12-flicker; do
  "$bin" eval detect --scenario "$out/$f.json5" --duration 12 2>&1 | grep "^| $f |" | cut -d'|' -f2-5
done
echo
echo "== eval acc, camera: noise-12-flicker"
"$bin" eval acc --scenario "$out/noise-12-flicker.json5" --logs "$out/logs" 2>&1 | grep -E "^\| (scenario|noise)" || true
