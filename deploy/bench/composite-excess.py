#!/usr/bin/env python3
"""Ranks where a composite bench loses its decibels, and compares runs.

`visage bench composites --json` reports, per recipe and group, the
composite's PSNR and the ceiling (the group's source on its own truth),
and per region the same over the border band and the interior. A
dB figure hides how many pixels it covers: a mouth group 6 dB under its
ceiling can cost its recipe more than a face group 3 dB under. This turns
each group's PSNR back into a sum of squared errors (10^(-PSNR/10) times
its pixels, colours in 0..1) and prints, per recipe, each group's excess
over its ceiling as a share of the recipe's whole error, largest first,
then the regions that cost most, band and interior apart.

  deploy/bench/composite-excess.py RUN.json            # where RUN loses
  deploy/bench/composite-excess.py BEFORE.json AFTER.json [...]
                                                       # means and recipes side by side

Make a RUN with `visage bench composites --pipeline ours --json > RUN.json`.
"""
import json
import sys

# Regions listed per recipe (largest excess over the ceiling first).
REGIONS = 4

MEANS = ("psnr_db", "ceiling_psnr_db", "border_psnr_db", "interior_psnr_db",
         "ceiling_border_psnr_db", "ceiling_interior_psnr_db",
         "skin_delta_e", "non_skin_delta_e", "holes_percent")


def sse(psnr_db, pixels):
    return 10 ** (-psnr_db / 10) * pixels


def excess(run):
    for recipe in run["recipes"]:
        report = recipe["report"]
        whole = sse(report["quality"]["psnr_db"], report["quality"]["pixels"])
        rows = []
        for group in report["groups"]:
            q = group["quality"]
            if q["pixels"] == 0 or group.get("ceiling_psnr_db") is None:
                continue
            lost = sse(q["psnr_db"], q["pixels"]) - sse(group["ceiling_psnr_db"], q["pixels"])
            rows.append((lost / whole, group["group"], group["source"], q["psnr_db"],
                         group["ceiling_psnr_db"], q["pixels"]))
        print(f"{recipe['recipe']}: {report['quality']['psnr_db']:.2f} dB, "
              f"ceiling {report['ceiling']['psnr_db']:.2f} dB")
        for share, name, source, psnr, ceiling, pixels in sorted(rows, reverse=True):
            print(f"  {name:6} {source:6} {psnr:6.2f} dB (ceiling {ceiling:6.2f}) "
                  f"{pixels:7} px  over it by {100 * share:5.1f} % of the recipe's error")
        # Runs since session 28 also split each region into band and interior.
        for region in report.get("regions", [])[:REGIONS]:
            if region["excess"] <= 0:
                break
            print(f"    {region['region']:16} {region['source']:6} "
                  f"band {cell(region['band'])}/{number(region['ceiling_band_psnr_db'])} "
                  f"interior {cell(region['interior'])}/{number(region['ceiling_interior_psnr_db'])} dB  "
                  f"over it by {100 * region['excess'] / whole:5.1f} % of the recipe's error")


def number(db):
    return f"{db:5.2f}" if isinstance(db, (int, float)) else "    -"


def cell(quality):
    return number(quality["psnr_db"]) if quality["pixels"] else "    -"


def compare(paths, runs):
    width = max(len(p) for p in paths)
    for path, run in zip(paths, runs):
        mean = run["mean"]
        print(f"{path:{width}}  " + "  ".join(f"{k} {mean[k]:.3f}" for k in MEANS if k in mean))
    for i, recipe in enumerate(runs[0]["recipes"]):
        cells = [f"{run['recipes'][i]['report']['quality']['psnr_db']:6.2f}" for run in runs]
        print(f"  {recipe['recipe']:22} " + " ".join(cells))


def main():
    paths = sys.argv[1:]
    if not paths or any(p.startswith("-") for p in paths):
        print(__doc__.strip(), file=sys.stderr)
        sys.exit(2)
    try:
        runs = [json.load(open(p)) for p in paths]
    except (OSError, ValueError) as e:
        print(f"composite-excess: {e}", file=sys.stderr)
        sys.exit(2)
    if len(runs) == 1:
        excess(runs[0])
    else:
        compare(paths, runs)


if __name__ == "__main__":
    main()
