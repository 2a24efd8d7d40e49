#!/usr/bin/env bash
# Runs `slipstream eval acc` on the extra scenarios in tests/scenarios/ (ours, written from
# docs/simulator.md alone: phantom-braking layouts, far and slow leads, hard braking, dense
# traffic, other egos, noisy sensors) with each perception, and prints the result tables.
# Lockstep, so deterministic; about 5 minutes on 2 cores. Needs a release build
# (cargo build --release). scripts/test.sh runs a seeded sample of eight of them with both
# perceptions (tests/it/sweep.rs, the seed printed); this runs them all, before changing the
# ACC or the detector.
# Usage: scripts/check-scenarios.sh [OUT_DIR] (logs of failing runs are kept there)
# PERCEPTIONS="camera" limits the run to one perception.
set -euo pipefail
cd "$(dirname "$0")/.."
bin=target/release/slipstream
out=${1:-target/check-scenarios}
rm -rf "$out" && mkdir -p "$out"
args=()
for f in tests/scenarios/*.json5; do args+=(--scenario "$f"); done
status=0
for perception in ${PERCEPTIONS:-camera ground-truth}; do
  echo "== $perception"
  "$bin" eval acc --perception "$perception" "${args[@]}" --logs "$out/logs-$perception" \
    --plots "$out/plots" | tee "$out/$perception.md" || status=1
done
exit $status
