#!/usr/bin/env bash
# Runs every slipstream test, installing what the tests need first:
#   - system packages: iproute2 (network-namespace tests, tc for rate caps), iptables (random
#     drop on the namespace links), openssl (the security tests make their certificates),
#     python3 venv support;
#   - a Python venv in .venv with eclipse-zenoh 1.10, numpy and pytest (the Python client and
#     its examples run against the Rust nodes), mcap and mcap-ros2-support (independent readers
#     of recordings, slipstream's and ROS 2's),
#     websockets (an independent Foxglove WebSocket client of the live view), rosbags and
#     zenoh-ros2-sdk (independent ROS 2 CDR, type hashes and graph discovery, for the ROS 2
#     bridge; no ROS install), carla and coppeliasim-zmqremoteapi-client (the simulators' own
#     client packages, which the adapters use against stand-ins of their servers);
#   - the Rust tests of every crate of the workspace in the release profile, the profile of the
#     quick start's `cargo build --release`: no crate has dev-dependencies, and every crate
#     takes its dependencies from the workspace's one list with the same features, so after
#     that build no dependency (Zenoh included) compiles again; the example node
#     (examples/own-controller) builds on what is built already;
#   - `cargo install --path .` and `pip install ./clients/python[numpy]` into a scratch
#     directory, checked from outside the checkout (scripts/check-install.sh);
#   - the Python tests against the release binaries.
# Safe to run again: it installs only what is missing.
set -euo pipefail
cd "$(dirname "$0")/.."

step() { printf '\n== %s\n' "$*"; }

step "system packages"
missing=()
command -v ip >/dev/null 2>&1 || missing+=(iproute2)
command -v openssl >/dev/null 2>&1 || missing+=(openssl)
command -v tc >/dev/null 2>&1 || missing+=(iproute2)
command -v iptables >/dev/null 2>&1 || missing+=(iptables)
python3 -c 'import venv, ensurepip' >/dev/null 2>&1 || missing+=(python3-venv)
# A real browser for the view's page (tests/python/test_view_page.py).
command -v chromium >/dev/null 2>&1 || missing+=(chromium)
command -v chromedriver >/dev/null 2>&1 || missing+=(chromium-driver)
if ((${#missing[@]})); then
  if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then
    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "${missing[@]}"
  else
    echo "missing packages: ${missing[*]} (install them, e.g. sudo apt-get install ${missing[*]})" >&2
    exit 1
  fi
fi
echo "ok"

step "python venv (.venv) with eclipse-zenoh 1.10"
if ! .venv/bin/python -c 'import zenoh, numpy, cv2, pytest, xdist, mypy, mcap, mcap_ros2, websockets, rosbags, zenoh_ros2_sdk, carla, coppeliasim_zmqremoteapi_client, selenium' >/dev/null 2>&1; then
  python3 -m venv .venv
  .venv/bin/pip install --quiet --disable-pip-version-check 'eclipse-zenoh==1.10.*' numpy pytest pytest-xdist mypy mcap \
    mcap-ros2-support websockets 'rosbags==0.11.*' 'zenoh-ros2-sdk==0.1.*' 'carla==0.9.16' \
    'coppeliasim-zmqremoteapi-client==2.0.*' 'opencv-python-headless<5' 'selenium==4.*'
fi
# The Python client as its users install it (editable: the tests run against this checkout's
# code, imported as an installed package, not from a path the tests add).
.venv/bin/pip install --quiet --disable-pip-version-check -e 'clients/python[numpy,lz4,mcap,carla,coppeliasim]'
.venv/bin/python -c 'import zenoh; print("eclipse-zenoh", zenoh.__version__ if hasattr(zenoh, "__version__") else "installed")'

step "rust formatting (cargo fmt --check)"
cargo fmt --all --check
echo ok

step "rust build and tests (cargo test --release)"
rm -f target/test-reports/scenario-sample.txt target/test-reports/sweep-40.txt
SECONDS=0
# Every crate, the example node of docs/own-node.md included: the same features as the quick
# start's `cargo build --release` (the example needs nothing the tools do not), so nothing but
# the example compiles. Built alone (`-p`), a crate resolves the features of its own graph,
# and Zenoh compiles again.
cargo build --release --workspace
echo "build: ${SECONDS} s"

step "a loop beside the tests (default namespace, default config, as a developer leaves one running)"
# Every test runs in a network or a rendezvous of its own (tests/it/common.rs and
# tests/python/conftest.py hand every process a config without the machine's rendezvous; the
# commands typed as a user types them run on hosts of their own), so the tests pass with a
# loop running on the machine. This one checks it on every run: it holds the default
# rendezvous (tcp/127.0.0.1:7447) and namespace for the whole run, and at the end it must
# still be there, in the default namespace, with no command from any test applied.
beside_dir=target/test-reports/beside-loop
rm -rf "$beside_dir" && mkdir -p target/test-reports
target/release/slipstream up --perception ground-truth --scenario steady-follow --duration 36000 \
  --report "$beside_dir" --plain >target/test-reports/beside-loop.out 2>&1 &
beside=$!
trap 'kill -INT "$beside" 2>/dev/null || true' EXIT
for _ in $(seq 600); do
  grep -q "nodes alive: acc, sim, up" target/test-reports/beside-loop.out && break
  kill -0 "$beside" 2>/dev/null || { cat target/test-reports/beside-loop.out; exit 1; }
  sleep 0.1
done
grep -q "nodes alive: acc, sim, up" target/test-reports/beside-loop.out || { echo "the beside loop never came up"; exit 1; }
echo "running (pid $beside, report in $beside_dir)"

SECONDS=0
cargo test --release --workspace
echo "rust tests (compile included): ${SECONDS} s"

step "python client: type hints checked (mypy)"
.venv/bin/mypy --ignore-missing-imports clients/python/slipstream_client

step "installs as the README gives them (scripts/check-install.sh)"
bash scripts/check-install.sh

step "python tests (against target/release/slipstream)"
rm -f target/test-reports/netns.json
# Two workers, each taking whole files (a file's fixtures and its order kept): most tests wait
# on loops they drive, using about a quarter of two cores, so two at once halve the wall time.
# Every test's namespaces and ports are its own (pid-named namespaces, free ports). The
# commands of the README and docs/ run alone afterwards: they include realtime loops with a
# recorder, whose exit code says whether anything was lost, and a loaded machine loses.
# The slowest tests of each part are listed.
SLIPSTREAM_BIN="$PWD/target/release/slipstream" .venv/bin/python -m pytest -q -rs -n 2 --dist loadfile \
  --durations=8 --ignore tests/python/test_docs_commands.py tests/python
SLIPSTREAM_BIN="$PWD/target/release/slipstream" .venv/bin/python -m pytest -q -rs --durations=5 \
  tests/python/test_docs_commands.py

step "the loop beside the tests"
kill -0 "$beside" 2>/dev/null || { echo "the beside loop ended during the tests:"; tail -20 target/test-reports/beside-loop.out; exit 1; }
kill -INT "$beside"
beside_code=0
wait "$beside" || beside_code=$?
trap - EXIT
.venv/bin/python scripts/check-beside-loop.py "$beside_dir" "$beside_code"

for f in target/test-reports/scenario-sample.txt target/test-reports/sweep-40.txt; do
  if [ -f "$f" ]; then
    step "$(basename "$f" .txt) (tests/it/sweep.rs)"
    cat "$f"
  fi
done

if [ -f target/test-reports/netns.json ]; then
  step "namespace test: recovery times (docs/deployment.md)"
  cat target/test-reports/netns.json
fi
