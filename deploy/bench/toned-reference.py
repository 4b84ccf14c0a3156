#!/usr/bin/env python3
"""What the sources reach in the base's skin tone: a reference beside the ceiling.

The ceiling of `visage bench composites` is each source on its own ground
truth. A colour-corrected composite is measured against the `--tone base`
truth, where every swapped region wears the base's skin, and the skin
transfer that gets it there costs decibels on a source's own head already:
a dark source's training error is scaled up with its colours, and the
source lacks what the truth gives its skin from the base (freckles), or
keeps what the truth keeps (a beard) in Gaussians the transfer reads as
skin. This script measures that cost per (source, base) pair on a *toned
head* — every group's Gaussians and shape from the source, the base's
tone and motion, `colour = "semantic"` and nothing else — and combines it
per recipe into the **toned reference**: per region, the base's own
ceiling where the recipe shows the base, else the toned head's PSNR in
that region, weighted by the recipe's own pixels (band and interior). The
same combination of the plain ceiling is printed beside it as a check.

  deploy/bench/toned-reference.py heads --cache DIR --out HEADS
      # captures and evaluates each pair's toned head (and, with colour
      # off, the same head in its own tone), about 1 minute a pair at 256²
  deploy/bench/toned-reference.py combine RUN.json HEADS
      # per recipe: PSNR, ceiling and toned reference

RUN.json is `visage bench composites --pipeline ours --json` at the size
of the cache (`target/composite-sources/256x256-c8-f4-i1500-interior` for
`--size 256x256`); `--visage` names the binary (target/release/visage).
"""
import argparse
import json
import math
import pathlib
import subprocess
import sys
import tomllib

# The bench's recipes, wherever the script is run from.
RECIPES = pathlib.Path(__file__).resolve().parents[2] / "recipes" / "bench"
GROUPS = ("mouth", "eyes", "ears", "neck", "hair", "nose", "face")
POST = """[post]
smoothing = "off"
colour = "semantic"
membership = "place"
anchor = "nearest"
shading = "kept"
skin = "source"
"""


def pairs():
    """(source, base) of every swapped group of the bench's recipes."""
    found = set()
    for path in sorted(RECIPES.glob("*.toml")):
        recipe = tomllib.loads(path.read_text())
        base = recipe["base"]
        for group in recipe.get("groups", {}).values():
            source = group.get("gaussians", base)
            if source != base:
                found.add((source, base))
    return sorted(found)


def toned_recipe(source, base, colour):
    lines = [f'base = "{base}"']
    for group in GROUPS:
        lines += [f"[groups.{group}]", f'gaussians = "{source}"',
                  f"shape = {{ {source} = 1.0 }}"]
    return "\n".join(lines) + "\n" + POST.replace('"semantic"', f'"{colour}"')


def fail(message):
    """One line on standard error and exit 2, as visage does for bad input."""
    print(f"toned-reference: {message}", file=sys.stderr)
    sys.exit(2)


def run(args, what):
    try:
        done = subprocess.run(args, capture_output=True, text=True)
    except OSError as error:
        fail(f"cannot run {args[0]}: {error.strerror}")
    if done.returncode != 0:
        last = (done.stderr.strip().splitlines() or ["no message"])[-1]
        fail(f"{what} failed: {last}")
    return done.stdout


def read_json(path):
    try:
        return json.loads(path.read_text())
    except OSError as error:
        fail(f"cannot read {path}: {error.strerror}")
    except json.JSONDecodeError as error:
        fail(f"{path} is not JSON: {error}")


def heads(options):
    if not (options.cache / "ada" / "point_cloud.ply").is_file():
        fail(f"{options.cache} holds no trained bench sources (make them with "
             "`visage bench composites --size WxH`)")
    size = options.cache.name.split("-")[0]
    for source, base in pairs():
        folder = options.out / f"{source}-{base}"
        folder.mkdir(parents=True, exist_ok=True)
        for colour, tone, report in (("semantic", "base", "toned.json"),
                                     ("off", "source", "own-tone.json")):
            recipe = folder / f"{colour}.toml"
            recipe.write_text(toned_recipe(source, base, colour))
            truth = folder / f"truth-{tone}"
            run([options.visage, "capture", "--recipe", str(recipe), "--tone", tone,
                 "--seams", "hard", "--size", size, "--cameras", "8", "--frames", "4",
                 "-o", str(truth)], f"capture {source} on {base}")
            out = run([options.visage, "eval", "--composite", "--db", str(options.cache),
                       str(recipe), str(truth), "--seam-fit", "0", "--json"],
                      f"eval {source} on {base}")
            (folder / report).write_text(out)
        toned = read_json(folder / "toned.json")["quality"]["psnr_db"]
        own = read_json(folder / "own-tone.json")["quality"]["psnr_db"]
        print(f"{source} in {base}'s tone: {toned:.2f} dB (in its own tone {own:.2f} dB)")


def squared(psnr_db, pixels):
    return 10 ** (-psnr_db / 10) * pixels


def combine(options):
    run_json = read_json(options.run)
    if "recipes" not in run_json:
        fail(f"{options.run} is not the JSON of `visage bench composites`")
    bases = {p.stem: tomllib.loads(p.read_text())["base"] for p in RECIPES.glob("*.toml")}
    rows = []
    for recipe in run_json["recipes"]:
        base = bases.get(recipe["recipe"])
        if base is None:
            fail(f"{recipe['recipe']} is not one of {RECIPES}'s recipes")
        totals = [0.0, 0.0, 0.0, 0]
        for region in recipe["report"]["regions"]:
            source = region["source"]
            toned_region = None
            if source != base:
                head = read_json(options.heads / f"{source}-{base}" / "toned.json")
                toned_region = next((r["interior"]["psnr_db"] for r in head["regions"]
                                     if r["region"] == region["region"]), None)
            for zone, ceiling_key in (("band", "ceiling_band_psnr_db"),
                                      ("interior", "ceiling_interior_psnr_db")):
                figures = region[zone]
                if not figures or not figures["pixels"] or figures["psnr_db"] is None:
                    continue
                pixels = figures["pixels"]
                ceiling = region.get(ceiling_key)
                if ceiling is None:
                    ceiling = region["ceiling_interior_psnr_db"] or region["ceiling_band_psnr_db"]
                reference = toned_region if toned_region is not None else ceiling
                totals[0] += squared(figures["psnr_db"], pixels)
                totals[1] += squared(ceiling, pixels)
                totals[2] += squared(reference, pixels)
                totals[3] += pixels
        rows.append((recipe["recipe"], [-10 * math.log10(t / totals[3]) for t in totals[:3]]))
    means = [sum(psnr[k] for _, psnr in rows) / len(rows) for k in range(3)]
    print(f"{'recipe':24}{'PSNR':>8}{'ceiling':>9}{'toned':>8}   dB; ceiling and toned reference "
          "combined over the recipe's regions")
    for name, psnr in rows + [("mean", means)]:
        print(f"{name:24}{psnr[0]:8.2f}{psnr[1]:9.2f}{psnr[2]:8.2f}")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    commands = parser.add_subparsers(dest="command", required=True)
    make = commands.add_parser("heads")
    make.add_argument("--cache", type=pathlib.Path, required=True)
    make.add_argument("--out", type=pathlib.Path, required=True)
    make.add_argument("--visage", default="target/release/visage")
    join = commands.add_parser("combine")
    join.add_argument("run", type=pathlib.Path)
    join.add_argument("heads", type=pathlib.Path)
    options = parser.parse_args()
    heads(options) if options.command == "heads" else combine(options)


if __name__ == "__main__":
    main()
