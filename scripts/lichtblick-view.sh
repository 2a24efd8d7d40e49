#!/usr/bin/env bash
# The Foxglove path in a real viewer (opt-in, docs/viewing.md "In Lichtblick"): builds
# Lichtblick's web app from its source with packages from the npm registry, then
# scripts/lichtblick_view.py shows slipstream's live view and recordings in it under headless
# Chromium and saves the screenshots.
#
#   scripts/lichtblick-view.sh [LICHTBLICK_SOURCE_DIR] [-- lichtblick_view.py flags]
#
# LICHTBLICK_SOURCE_DIR: a checkout of github.com/lichtblick-suite/lichtblick (default:
# target/lichtblick-src, cloned at $LICHTBLICK_REF when missing). Needs node >= 20 and npm;
# about 1.5 GB of packages and 2 minutes of webpack on 2 cores. Safe to run again.
#
# What a checkout without Git LFS lacks is taken from npm: the repository keeps its yarn
# plugins and its fonts (Inter, IBM Plex Mono) in LFS, and the app waits for its fonts before
# it draws anything. Yarn 3 comes from the npm package @yarnpkg/cli-dist instead of corepack,
# and the fonts from @fontsource/inter and @fontsource/ibm-plex-mono (the same typefaces,
# latin subset).
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$PWD
SRC=${1:-$ROOT/target/lichtblick-src}
[ "${1:-}" ] && shift
[ "${1:-}" = "--" ] && shift
LICHTBLICK_REF=${LICHTBLICK_REF:-main}
TOOLS=$ROOT/target/lichtblick-tools

step() { printf '\n== %s\n' "$*"; }

step "source ($SRC)"
if [ ! -f "$SRC/package.json" ]; then
  git clone --depth 1 --branch "$LICHTBLICK_REF" https://github.com/lichtblick-suite/lichtblick.git "$SRC"
fi
grep -m1 '"version"' "$SRC/package.json"

step "yarn 3 and the fonts, from npm"
mkdir -p "$TOOLS"
if [ ! -f "$TOOLS/node_modules/@yarnpkg/cli-dist/bin/yarn.js" ]; then
  (cd "$TOOLS" && npm install --silent --no-audit --no-fund @yarnpkg/cli-dist@3.6.3 @fontsource/inter@5 @fontsource/ibm-plex-mono@5)
fi
YARN="node $TOOLS/node_modules/@yarnpkg/cli-dist/bin/yarn.js"
# The plugins and yarnPath point at LFS files; install needs neither.
sed -i -e '/^yarnPath:/d' -e '/^plugins:/,/^[^ ]/{/^plugins:/d;/^  /d}' "$SRC/.yarnrc.yml"
grep -q '^npmRegistryServer' "$SRC/.yarnrc.yml" || echo 'npmRegistryServer: "https://registry.npmjs.org"' >> "$SRC/.yarnrc.yml"
FONTS=$SRC/packages/suite-base/src/styles/assets
INTER=$TOOLS/node_modules/@fontsource/inter/files
PLEX=$TOOLS/node_modules/@fontsource/ibm-plex-mono/files
for pair in Inter-Regular:400-normal Inter-Italic:400-italic Inter-Medium:500-normal Inter-MediumItalic:500-italic \
            Inter-SemiBold:600-normal Inter-SemiBoldItalic:600-italic; do
  cp "$INTER/inter-latin-${pair#*:}.woff2" "$FONTS/${pair%%:*}.woff2"
done
for pair in PlexMono:400-normal PlexMono-Italic:400-italic PlexMono-Bold:700-normal PlexMono-BoldItalic:700-italic; do
  cp "$PLEX/ibm-plex-mono-latin-${pair#*:}.woff2" "$FONTS/${pair%%:*}.woff2"
done
echo ok

step "install (yarn, npm registry)"
(cd "$SRC" && ELECTRON_SKIP_BINARY_DOWNLOAD=1 PUPPETEER_SKIP_DOWNLOAD=1 YARN_ENABLE_TELEMETRY=0 \
  $YARN install --mode=skip-build)

step "build the web app (webpack, production)"
(cd "$SRC" && NODE_OPTIONS=--max-old-space-size=6144 $YARN web:build:prod)

step "slipstream's view and recordings in Lichtblick"
[ -x target/release/slipstream ] || cargo build --release --workspace
.venv/bin/python scripts/lichtblick_view.py --lichtblick "$SRC/web/.webpack" "$@"
