#!/bin/bash
# GPU measurements for a machine with a hardware GPU (a lent device, a GPU
# server): the renderer at 1M and 20M Gaussians, the level of detail, and the
# trainer at 512², each as JSON in OUT_DIR, plus the GPU kernel tests when a
# test binary is given. Each step has its own time limit so one slow step
# does not cost the rest.
#
#   deploy/gpu-check.sh VISAGE_BINARY OUT_DIR [RENDER_TEST_BINARY]
#
# Run it from a checkout (the kernel tests read crates/render/shaders).
#
# RENDER_TEST_BINARY: `cargo test -p visage-render --release --no-run` prints
# its path (target/release/deps/visage_render-*); its `gpu::` tests compare
# the kernels with the CPU and the two tile rasterisers bit for bit.
set -u
visage=${1:?usage: deploy/gpu-check.sh VISAGE_BINARY OUT_DIR [RENDER_TEST_BINARY]}
out=${2:?usage: deploy/gpu-check.sh VISAGE_BINARY OUT_DIR [RENDER_TEST_BINARY]}
tests=${3:+$(realpath "$3")}
out=$(realpath -m "$out")
mkdir -p "$out"
export NODEVICE_SELECT=1

step() { # name seconds command...
    local name=$1 seconds=$2
    shift 2
    echo "== $name ($(date +%T))"
    timeout "$seconds" "$@" >"$out/$name.json" 2>"$out/$name.err"
    echo "   exit $?"
}

step device 30 "$visage" bench render --synthetic-scale 1000 --sizes 64x64 \
    --renderers gpu --no-knobs --iterations 1 --warmup 0 --json
step render-1m 90 "$visage" bench render --synthetic-scale 1000000 \
    --sizes 200x120,1280x720,1920x1080 --renderers gpu --lod auto --no-knobs --json
step render-20m 150 "$visage" bench render --synthetic-scale 20000000 \
    --sizes 200x120,1920x1080 --renderers gpu --lod auto --no-knobs \
    --iterations 5 --warmup 1 --json
dataset=$(mktemp -d)/ada512
echo "== capture 512² ($(date +%T))"
timeout 150 "$visage" capture --size 512x512 -o "$dataset" >"$out/capture.err" 2>&1
echo "   exit $?"
step train-512 180 "$visage" bench train --dataset "$dataset" --iterations 300 \
    --eval-every 100 --renderers gpu --json
if [ -n "$tests" ]; then
    echo "== kernel tests ($(date +%T))"
    # From the crate's folder: a test reads the shaders beside it.
    # One at a time: with twenty devices open at once in one process the
    # NVIDIA driver once hung and once crashed (an H100, driver 580).
    (cd "$(dirname "$0")/../crates/render" && timeout 120 "$tests" gpu:: --test-threads=1) >"$out/kernel-tests.txt" 2>&1
    echo "   exit $?"
fi
echo "== done ($(date +%T))"
