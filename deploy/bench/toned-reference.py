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
      # per recipe: PSNR, ceiling, toned reference, and the same heads in
      # their own tone (a control: what a head of the source's own shape
      # under the base's motion costs before any transfer)

RUN.json is `visage bench composites --pipeline ours --json` at the size
of the cache (`target/composite-sources/256x256-c8-f4-i1500-interior` for
`--size 256x256`); `--visage` names the binary (the repository's
target/release/visage by default). Python 3.11 or later (tomllib).
"""
import argparse
import functools
import json
import math
import pathlib
import subprocess
import sys
import tomllib

# The repository, and in it the bench's recipes, wherever the script is run from.
REPOSITORY = pathlib.Path(__file__).resolve().parents[2]
RECIPES = REPOSITORY / "recipes" / "bench"
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


def rig(cache):
    """Size, cameras and timesteps of a bench cache named WxH-cN-fN-iN-…"""
    parts = cache.name.split("-")
    if (len(parts) < 3 or "x" not in parts[0] or not parts[1].startswith("c")
            or not parts[2].startswith("f")):
        fail(f"{cache} is not named as `visage bench composites` names its cache (WxH-cN-fN-…)")
    return parts[0], parts[1][1:], parts[2][1:]


def heads(options):
    if not (options.cache / "ada" / "point_cloud.ply").is_file():
        fail(f"{options.cache} holds no trained bench sources (make them with "
             "`visage bench composites --size WxH`)")
    size, cameras, frames = rig(options.cache)
    for source, base in pairs():
        folder = options.out / f"{source}-{base}"
        try:
            folder.mkdir(parents=True, exist_ok=True)
        except OSError as error:
            fail(f"cannot make {folder}: {error.strerror}")
        for colour, tone, report in (("semantic", "base", "toned.json"),
                                     ("off", "source", "own-tone.json")):
            recipe = folder / f"{colour}.toml"
            recipe.write_text(toned_recipe(source, base, colour))
            truth = folder / f"truth-{tone}"
            run([options.visage, "capture", "--recipe", str(recipe), "--tone", tone,
                 "--seams", "hard", "--size", size, "--cameras", cameras, "--frames", frames,
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


@functools.cache
def head_regions(folder, report):
    """Region name → interior PSNR of one toned head's report (a toned
    head has no band: its interior is the whole region); each report is
    read once, however many regions and recipes ask."""
    head = read_json(folder / report)
    if not isinstance(head, dict) or "regions" not in head:
        fail(f"{folder / report} is not the JSON of `visage eval --composite`")
    return {r["region"]: (r.get("interior") or {}).get("psnr_db") for r in head["regions"]}


def recipe_row(recipe, base, heads_folder):
    """PSNR, ceiling, toned reference and own-tone control of one recipe,
    each a squared error over the recipe's own band and interior pixels."""
    totals = [0.0, 0.0, 0.0, 0.0, 0]
    for region in recipe["report"]["regions"]:
        name, source = region["region"], region["source"]
        references = None
        if source != base:
            folder = heads_folder / f"{source}-{base}"
            references = [head_regions(folder, report).get(name)
                          for report in ("toned.json", "own-tone.json")]
            if None in references:
                fail(f"the toned head {source}-{base} shows no {name}: "
                     "its reference would be guessed")
        for zone, ceiling_key in (("band", "ceiling_band_psnr_db"),
                                  ("interior", "ceiling_interior_psnr_db")):
            figures = region[zone]
            if not figures or not figures["pixels"] or figures["psnr_db"] is None:
                continue
            ceiling = next((region.get(k) for k in (ceiling_key, "ceiling_interior_psnr_db",
                                                    "ceiling_band_psnr_db")
                            if region.get(k) is not None), None)
            if ceiling is None:
                fail(f"{recipe['recipe']}'s {name} has no ceiling")
            pixels = figures["pixels"]
            toned, own = references or (ceiling, ceiling)
            for k, psnr in enumerate((figures["psnr_db"], ceiling, toned, own)):
                totals[k] += squared(psnr, pixels)
            totals[4] += pixels
    if not totals[4]:
        fail(f"{recipe['recipe']} has no region with pixels")
    return [-10 * math.log10(t / totals[4]) for t in totals[:4]]


def combine(options):
    run_json = read_json(options.run)
    if not isinstance(run_json, dict) or not run_json.get("recipes"):
        fail(f"{options.run} is not the JSON of `visage bench composites` (no recipes)")
    bases = {p.stem: tomllib.loads(p.read_text())["base"] for p in RECIPES.glob("*.toml")}
    rows = []
    for recipe in run_json["recipes"]:
        base = bases.get(recipe["recipe"])
        if base is None:
            fail(f"{recipe['recipe']} is not one of {RECIPES}'s recipes")
        rows.append((recipe["recipe"], recipe_row(recipe, base, options.heads)))
    means = [sum(row[k] for _, row in rows) / len(rows) for k in range(4)]
    print(f"{'recipe':24}{'PSNR':>8}{'ceiling':>9}{'toned':>8}{'own tone':>10}")
    for name, row in rows + [("mean", means)]:
        print(f"{name:24}{row[0]:8.2f}{row[1]:9.2f}{row[2]:8.2f}{row[3]:10.2f}")
    print("dB over each recipe's own pixels; toned: each swapped source's region as its toned "
          "head shows it, the base's as its ceiling; own tone: the same heads with colour off "
          "against their own tone's truth (what the heads cost before any transfer)")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    commands = parser.add_subparsers(dest="command", required=True)
    make = commands.add_parser("heads")
    make.add_argument("--cache", type=pathlib.Path, required=True)
    make.add_argument("--out", type=pathlib.Path, required=True)
    make.add_argument("--visage", default=str(REPOSITORY / "target" / "release" / "visage"))
    join = commands.add_parser("combine")
    join.add_argument("run", type=pathlib.Path)
    join.add_argument("heads", type=pathlib.Path)
    options = parser.parse_args()
    heads(options) if options.command == "heads" else combine(options)


if __name__ == "__main__":
    main()
