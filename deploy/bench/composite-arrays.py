#!/usr/bin/env python3
"""Takes a composite's error apart pixel by pixel, from `eval --arrays`.

`visage eval --composite RECIPE TRUTH --db SOURCES --arrays DIR` writes one
numpy archive per view: the composite, its ground truth, the head, band,
region and source labels, and each used source's own render and truth (the
ceiling). `composite-excess.py` ranks groups from a bench's JSON; this reads
the pixels, for the questions the JSON cannot answer:

  deploy/bench/composite-arrays.py regions DIR [BEFORE_DIR]
      Per region, band or interior, and source: pixels, the composite's dB,
      the source's own dB on that region (its ceiling, in its own tone), and
      the share of the recipe's squared error there, largest first. With
      BEFORE_DIR (the same recipe's arrays from another run, e.g. with
      `--seam-fit 0`), each row's dB before and its change in squared error:
      where a change helps and where it hurts.

  deploy/bench/composite-arrays.py edge DIR REGIONS_A REGIONS_B
      The error across the border between two sets of regions (comma
      separated names, e.g. `skin` and `hair` for a hairline), by distance
      in pixels (chessboard, up to 6; negative on A's side): pixels, the
      truth's mean lightness, the composite's mean signed error per channel
      and its root mean square. A blur shows as opposite biases on the two
      sides of d = 0.

Colours are the archives' display RGB in 0..1; a squared error is summed
over the three channels, as the evaluator's PSNR reads it. Needs numpy.
"""
import glob
import os
import sys
from collections import defaultdict

import numpy as np

EDGE_PX = 6


def names(rows):
    return ["".join(chr(c) for c in row if c) for row in rows]


def views(folder):
    paths = sorted(glob.glob(os.path.join(folder, "*.npz")))
    if not paths:
        raise ValueError(f"{folder} holds no .npz archives (make them with eval --arrays)")
    for path in paths:
        yield os.path.basename(path), np.load(path)


def squared_error(a, b):
    return ((a.astype(np.float64) - b.astype(np.float64)) ** 2).sum(-1)


def db(sse, pixels):
    return 10 * np.log10(3 * pixels / sse) if sse > 0 and pixels else float("inf")


def tally(folder):
    """Squared error and pixels per (region, band, source), the whole head's
    squared error, and each source's own squared error and pixels per region."""
    rows = defaultdict(lambda: [0.0, 0])
    ceilings = defaultdict(lambda: [0.0, 0])
    whole = 0.0
    for _, z in views(folder):
        regions, sources = names(z["region_names"]), names(z["source_names"])
        head = z["head"] == 1
        band = z["band"] == 1
        error = squared_error(z["composite"], z["truth"])
        whole += error[head].sum()
        for r in np.unique(z["region"][head]):
            for in_band in (False, True):
                mask = head & (z["region"] == r) & (band == in_band)
                if mask.any():
                    source = sources[np.bincount(z["source"][mask]).argmax()]
                    row = rows[(regions[r], in_band, source)]
                    row[0] += error[mask].sum()
                    row[1] += int(mask.sum())
        for s in sources:
            key = f"ceiling_{s}"
            if key not in z.files:
                continue
            own = squared_error(z[key], z[key + "_truth"])
            shown = z[key + "_region"]
            for r in np.unique(shown[shown >= 0]):
                cell = ceilings[(regions[r], s)]
                cell[0] += own[shown == r].sum()
                cell[1] += int((shown == r).sum())
    return rows, ceilings, whole


def regions(folder, before=None):
    rows, ceilings, whole = tally(folder)
    earlier = tally(before)[0] if before else {}
    print(f"{folder}: {db(whole, sum(n for _, n in rows.values())):.3f} dB over the head")
    for key in sorted(rows, key=lambda k: -rows[k][0]):
        region, in_band, source = key
        sse, pixels = rows[key]
        own = ceilings.get((region, source))
        ceiling = f"{db(own[0] / own[1] * pixels, pixels):6.2f}" if own and own[1] else "     -"
        line = (f"  {region:16} {'band' if in_band else 'in':4} {source:8} {pixels:8d} px "
                f"{db(sse, pixels):6.2f} dB (own {ceiling}) {100 * sse / whole:5.1f} %")
        if key in earlier:
            then = earlier[key][0]
            line += f"  before {db(then, pixels):6.2f} dB, error {sse - then:+8.2f}"
        print(line)


def distance(mask):
    """Chessboard distance in pixels from each pixel to `mask` (0 on it),
    EDGE_PX + 1 past EDGE_PX."""
    out = np.where(mask, 0, EDGE_PX + 1)
    reached = mask.copy()
    for d in range(1, EDGE_PX + 1):
        grown = reached.copy()
        padded = np.pad(reached, 1)
        for dy in (-1, 0, 1):
            for dx in (-1, 0, 1):
                grown |= padded[1 + dy:padded.shape[0] - 1 + dy, 1 + dx:padded.shape[1] - 1 + dx]
        out[grown & ~reached] = d
        reached = grown
    return out


def edge(folder, side_a, side_b):
    acc = defaultdict(lambda: [0, 0.0, np.zeros(3), 0.0])
    for _, z in views(folder):
        regions = names(z["region_names"])
        unknown = [n for n in side_a + side_b if n not in regions]
        if unknown:
            raise ValueError(f"no region named {', '.join(unknown)} (regions: {', '.join(regions)})")
        head = z["head"] == 1
        a = head & np.isin(z["region"], [regions.index(n) for n in side_a])
        b = head & np.isin(z["region"], [regions.index(n) for n in side_b])
        signed = np.where(a, -distance(b), distance(a))
        near = (a | b) & (np.abs(signed) <= EDGE_PX)
        diff = z["composite"].astype(np.float64) - z["truth"].astype(np.float64)
        light = z["truth"].astype(np.float64).mean(-1)
        for d in range(-EDGE_PX, EDGE_PX + 1):
            mask = near & (signed == d)
            if mask.any():
                cell = acc[d]
                cell[0] += int(mask.sum())
                cell[1] += light[mask].sum()
                cell[2] += diff[mask].sum(0)
                cell[3] += (diff[mask] ** 2).sum()
    print(f"{folder}: {','.join(side_a)} (d < 0) against {','.join(side_b)} (d > 0)")
    for d in sorted(acc):
        n, light, bias, sq = acc[d]
        r, g, b = bias / n
        print(f"  d {d:+d} {n:7d} px  truth {light / n:.3f}  error {r:+.4f} {g:+.4f} {b:+.4f}"
              f"  rms {np.sqrt(sq / n / 3):.4f}")


def main():
    args = sys.argv[1:]
    try:
        if len(args) in (2, 3) and args[0] == "regions":
            regions(*args[1:])
        elif len(args) == 4 and args[0] == "edge":
            edge(args[1], args[2].split(","), args[3].split(","))
        else:
            print(__doc__.strip(), file=sys.stderr)
            sys.exit(2)
    except (OSError, ValueError, KeyError) as e:
        print(f"composite-arrays: {e}", file=sys.stderr)
        sys.exit(2)


if __name__ == "__main__":
    main()
