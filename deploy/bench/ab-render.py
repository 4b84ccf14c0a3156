#!/usr/bin/env python3
"""Compares `visage` builds on the scene bench, interleaved.

Timings on shared machines drift by +-15 % for minutes at a time, so a
single run of each build cannot tell a 10 % change. This runs every build
in turn, ROUNDS times, and reports per build the minimum of each stage
over the rounds and the median of the rounds' medians.

  deploy/bench/ab-render.py ROUNDS BUILD [BUILD ...] [-- EXTRA BENCH ARGS]

A BUILD is a path to a `visage` binary (copy `target/release/visage`
aside before rebuilding). The default bench is the exact million at
200x120 on the CPU renderer; arguments after `--` are added to it
(a later `--sizes` or `--synthetic-scale` overrides the default).
"""
import json
import subprocess
import sys


DEFAULTS = {"--synthetic-scale": "1000000", "--sizes": "200x120",
            "--renderers": "cpu", "--iterations": "7", "--warmup": "2",
            "--lod": "off"}


def bench(build, extra):
    options = [arg for pair in DEFAULTS.items() if pair[0] not in extra for arg in pair]
    cmd = [build, "bench", "render"] + options + ["--no-knobs", "--json"] + extra
    run = subprocess.run(cmd, capture_output=True, text=True)
    if run.returncode != 0:
        sys.exit(f"{build}: {run.stderr.strip()}")
    report = json.loads(run.stdout)
    return report["renderers"][0]["rows"]


def main():
    args = sys.argv[1:]
    if len(args) < 2 or not args[0].isdigit():
        sys.exit(__doc__)
    rounds, builds, extra = int(args[0]), args[1:], []
    if "--" in builds:
        k = builds.index("--")
        builds, extra = builds[:k], builds[k + 1:]
    seen = {b: {} for b in builds}
    for _ in range(rounds):
        for b in builds:
            for row in bench(b, extra):
                size = f"{row['width']}x{row['height']}"
                seen[b].setdefault(size, []).append(row)
    for b in builds:
        for size, rows in seen[b].items():
            stages = {s: min(r["stages_ms"][s] for r in rows)
                      for s in ("project", "sort", "rasterize")}
            medians = sorted(r["ms_median"] for r in rows)
            print(f"{b} {size}: min {min(medians):.1f} ms "
                  f"(project {stages['project']:.1f}, sort {stages['sort']:.1f}, "
                  f"raster {stages['rasterize']:.1f}), median of medians "
                  f"{medians[len(medians) // 2]:.1f} ms, {rows[0]['psnr_db']:.1f} dB")


if __name__ == "__main__":
    main()
