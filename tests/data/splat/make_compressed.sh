#!/usr/bin/env bash
# SuperSplat's compressed PLY and PlayCanvas's own tool, both ways (needs node,
# npm and cargo; the outputs are committed, CI needs neither node nor npm):
#   bash tests/data/splat/make_compressed.sh
# - ring.compressed.ply, ring3.compressed.ply: splat-transform 3.7.0 compressed
#   ring.ply and ring3.ply (visage's reader is tested against them);
# - ring3.visage.compressed.ply: visage's own writer (`visage convert`);
# - ring3.visage.decoded.ply: that file as splat-transform decodes it (visage's
#   reading of its own output is tested against the tool's).
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
tool="$(mktemp -d)"
(cd "$tool" && npm install --silent @playcanvas/splat-transform@3.7.0)
cli="$tool/node_modules/@playcanvas/splat-transform/bin/cli.mjs"
for name in ring ring3; do
  node "$cli" -w "$here/$name.ply" "$here/$name.compressed.ply"
done
(cd "$here/../../.." && cargo run --release -q -- convert "$here/ring3.ply" "$here/ring3.visage.compressed.ply")
node "$cli" -w "$here/ring3.visage.compressed.ply" "$here/ring3.visage.decoded.ply"
rm -rf "$tool"
