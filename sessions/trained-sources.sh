#!/bin/sh
# Builds the trained-source database sessions/trained-sources.vsg composes:
# captures three built-in sources on the front arc and trains each with
# visage's own trainer (hole filling on), into DIR (default
# target/trained-sources). Usage: sessions/trained-sources.sh [DIR] [ITERATIONS] [SIZE]
set -eu
dir=${1:-target/trained-sources}
iterations=${2:-1500}
size=${3:-128x128}
visage=${VISAGE:-visage}
scratch=$(mktemp -d)
trap 'rm -rf "$scratch"' EXIT
mkdir -p "$dir"
for source in ada bram jomo; do
    "$visage" capture --source "$source" --size "$size" --frames 8 -o "$scratch/$source"
    "$visage" train "$scratch/$source" -o "$dir/$source" --iterations "$iterations" \
        --checkpoint-every 0
    rm -f "$dir/$source/checkpoint.npz"
done
echo "trained sources in $dir"
