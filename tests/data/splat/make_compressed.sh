#!/usr/bin/env bash
# SuperSplat's compressed PLY made by PlayCanvas's own tool, so visage's reader
# is tested against files it did not write (needs node and npm; the outputs are
# committed, CI needs neither):
#   bash tests/data/splat/make_compressed.sh
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
tool="$(mktemp -d)"
(cd "$tool" && npm install --silent @playcanvas/splat-transform@3.7.0)
cli="$tool/node_modules/@playcanvas/splat-transform/bin/cli.mjs"
for name in ring ring3; do
  node "$cli" -w "$here/$name.ply" "$here/$name.compressed.ply"
done
rm -rf "$tool"
