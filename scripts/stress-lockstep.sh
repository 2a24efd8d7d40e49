#!/usr/bin/env bash
# Issue 41's io_uring verdict: the lockstep determinism run repeated under load (two busy
# threads) until it stalls or SLIPSTREAM_STRESS_RUNS (default 50) pass, on the default build
# and on a build with Zenoh's io_uring receive path (`--features uring`, its own target
# directory: Zenoh is compiled a second time, ~8 minutes on 2 cores). A stall leaves every
# thread's stack in target/test-reports/lockstep-stall-<run>.txt (gdb).
#   scripts/stress-lockstep.sh            both builds
#   scripts/stress-lockstep.sh uring      the io_uring build only
set -euo pipefail
cd "$(dirname "$0")/.."
export SLIPSTREAM_STRESS_RUNS="${SLIPSTREAM_STRESS_RUNS:-50}"
run() {
    echo "== lockstep stress, $1 ($SLIPSTREAM_STRESS_RUNS runs under load)"
    shift
    "$@" --release --test it lockstep_stress_under_load -- --ignored --nocapture
}
if [[ "${1:-both}" != "uring" ]]; then
    run "default build" cargo test
fi
URING_TARGET="${URING_TARGET:-/tmp/slipstream-uring}"
CARGO_TARGET_DIR="$URING_TARGET" run "io_uring build (target $URING_TARGET)" cargo test --features uring
