#!/usr/bin/env bash
# Niantic's SPZ made and read by Niantic's own library (github.com/nianticlabs/spz
# at 21715c3; needs git, cmake, g++, zlib and libzstd; the outputs are
# committed, CI needs none of them):
#   bash tests/data/splat/make_spz.sh [SPZ_SOURCE_DIR]
# - ring3.spz: `ply_to_spz ring3.ply` (version 4, zstd streams, the library's
#   default 5/4-bit SH quantisation); ring3.spz.decoded.ply: `spz_to_ply` of it;
# - ring3.v3.spz, ring.v2.spz: the legacy gzip versions 3 and 2, written by the
#   library through spz_version.cc; ring.v2.spz.decoded.ply: `spz_to_ply` of the
#   v2 file (v3's decoding is byte-identical to ring3.spz.decoded.ply);
# - ring3.visage.spz: visage's writer (`visage convert ring3.ply`);
#   ring3.visage.spz.decoded.ply: that file as `spz_to_ply` decodes it.
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
src="${1:-}"
work="$(mktemp -d)"
if [ -z "$src" ]; then
  git clone -q https://github.com/nianticlabs/spz "$work/spz"
  git -C "$work/spz" checkout -q 21715c3
  src="$work/spz"
fi
cmake -S "$src" -B "$work/build" -DCMAKE_BUILD_TYPE=Release > /dev/null
cmake --build "$work/build" -j 2 > /dev/null
g++ -O2 -I "$src/src/cc" "$here/spz_version.cc" "$work/build/libspz.a" -lz -lzstd -o "$work/spz_version"
"$work/build/ply_to_spz" "$here/ring3.ply" "$here/ring3.spz"
"$work/build/spz_to_ply" "$here/ring3.spz" "$here/ring3.spz.decoded.ply"
"$work/spz_version" "$here/ring3.ply" "$here/ring3.v3.spz" 3
"$work/spz_version" "$here/ring.ply" "$here/ring.v2.spz" 2
"$work/build/spz_to_ply" "$here/ring.v2.spz" "$here/ring.v2.spz.decoded.ply"
(cd "$here/../../.." && cargo run --release -q -- convert "$here/ring3.ply" "$here/ring3.visage.spz")
"$work/build/spz_to_ply" "$here/ring3.visage.spz" "$here/ring3.visage.spz.decoded.ply"
rm -rf "$work"
