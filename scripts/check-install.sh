#!/usr/bin/env bash
# The two installs the README gives, as a user runs them, into a scratch directory that is
# removed at the end:
#   - `cargo install --path .`: the four commands land in the root's bin/, report the
#     package's version, and work outside this checkout (built-in config, scenarios, help,
#     man pages, completions);
#   - `pip install ./clients/python[numpy]` into a fresh venv (not editable): the package
#     imports from site-packages with its py.typed marker, and decodes what the Rust encoder
#     wrote.
# scripts/test.sh runs it after the release build: `--target-dir target` reuses that build's
# artifacts, so nothing compiles again. Exits non-zero on the first check that fails.
set -euo pipefail
cd "$(dirname "$0")/.."
root=$PWD
scratch=$(mktemp -d)
trap 'rm -rf "$scratch"' EXIT

fail() { echo "check-install: $*" >&2; exit 1; }

cargo install --quiet --path . --locked --root "$scratch/cargo" --target-dir target
version=$(sed -n 's/^version = "\(.*\)"/\1/p' Cargo.toml | head -1)
for b in slipstream slipstream-sim slipstream-detect slipstream-acc; do
  [ -x "$scratch/cargo/bin/$b" ] || fail "cargo install left no $b"
  "$scratch/cargo/bin/$b" --version | grep -qx "$b $version" || fail "$b --version is not '$b $version'"
done

# Outside the checkout: no config/ here, so every command runs on its built-in defaults.
mkdir -p "$scratch/elsewhere" && cd "$scratch/elsewhere"
bin=$scratch/cargo/bin
"$bin/slipstream" info --json | python3 -c 'import json, sys; i = json.load(sys.stdin); assert i["topics"], i' \
  || fail "slipstream info --json outside the checkout"
"$bin/slipstream-sim" --list-scenarios | grep -q '^cut-in' || fail "slipstream-sim --list-scenarios has no cut-in"
"$bin/slipstream" man "$scratch/man"
[ -s "$scratch/man/slipstream.1" ] && [ -s "$scratch/man/slipstream-up.1" ] || fail "slipstream man wrote no pages"
"$bin/slipstream" completions bash | grep -q '_slipstream()' || fail "no bash completion"
"$bin/slipstream" wire-examples > "$scratch/examples.json"
cd "$root"

# The Python client as a user installs it: a fresh venv, a copy into site-packages.
python3 -m venv "$scratch/venv"
"$scratch/venv/bin/pip" install --quiet --disable-pip-version-check "./clients/python[numpy]"
cd "$scratch/elsewhere"
"$scratch/venv/bin/python" - "$scratch/examples.json" <<'EOF'
import json, pathlib, sys
import slipstream_client
from slipstream_client import KINDS, decode
from slipstream_client.mcap_decoder import DecoderFactory  # noqa: F401 (imports without mcap)

package = pathlib.Path(slipstream_client.__file__).parent
assert "site-packages" in str(package), f"imported from {package}, not the installed copy"
assert (package / "py.typed").is_file(), "py.typed is not installed"
examples = json.load(open(sys.argv[1]))
for e in examples:
    kind, header, body = decode(bytes.fromhex(e["hex"].replace(" ", "")))
    assert kind == e["kind"], (kind, e["kind"])
assert {e["kind"] for e in examples} == set(KINDS.values())
print(f"check-install: 4 commands and the Python client installed; {len(examples)} example payloads decoded")
EOF
