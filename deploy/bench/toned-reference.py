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
  deploy/bench/toned-reference.py trained --cache DIR --heads HEADS
      # trains each pair's source on its toned head's truth (the base's
      # tone) as the bench trains its sources, and measures it there: what
      # the source reaches in that tone when trained in it, with no
      # transfer at all; about 1¾ minutes a pair at 256², and a pair already
      # trained is kept
  deploy/bench/toned-reference.py combine RUN.json HEADS
      # per recipe: PSNR, ceiling, toned reference, and the same heads in
      # their own tone (a control: what a head of the source's own shape
      # under the base's motion costs before any transfer); with `trained`
      # run, also the *toned ceiling*: each swapped region as its source
      # trained in the base's tone shows it

RUN.json is `visage bench composites --pipeline ours --json` at the size
of the cache (`target/composite-sources/256x256-c8-f4-i1500-interior` for
`--size 256x256`); `--visage` names the binary (the repository's
target/release/visage by default). Python 3.11 or later (tomllib).
"""
import argparse
import functools
import json
import math
import os
import pathlib
import shutil
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


def evaluate(visage, database, recipe, truth, what):
    """`visage eval --composite` of a toned head without the seam fit, as JSON."""
    return run([visage, "eval", "--composite", "--db", str(database), str(recipe),
                str(truth), "--seam-fit", "0", "--json"], f"eval {what}")


def write_atomically(path, text):
    """Writes a report whole or not at all: a kill mid-write leaves no
    truncated JSON that a later step would take as a finished figure."""
    partial = path.with_name(path.name + ".partial")
    try:
        partial.write_text(text)
        os.replace(partial, path)
    except OSError as error:
        fail(f"cannot write {path}: {error.strerror}")


def forget_trained(folder):
    """Removes what `trained` made of a pair, whose truth is about to change."""
    for made in ("trained", "trained.partial", "trained-db"):
        shutil.rmtree(folder / made, ignore_errors=True)
    (folder / "trained.json").unlink(missing_ok=True)


def read_json(path):
    try:
        return json.loads(path.read_text())
    except OSError as error:
        fail(f"cannot read {path}: {error.strerror}")
    except json.JSONDecodeError as error:
        fail(f"{path} is not JSON: {error}")


def rig(cache):
    """Size, cameras, timesteps and training iterations of a bench cache
    named WxH-cN-fN-iN-…"""
    parts = cache.name.split("-")
    if (len(parts) < 4 or "x" not in parts[0] or not parts[1].startswith("c")
            or not parts[2].startswith("f") or not parts[3].startswith("i")):
        fail(f"{cache} is not named as `visage bench composites` names its cache (WxH-cN-fN-iN-…)")
    return parts[0], parts[1][1:], parts[2][1:], parts[3][1:]


def check_cache(cache):
    if not (cache / "ada" / "point_cloud.ply").is_file():
        fail(f"{cache} holds no trained bench sources (make them with "
             "`visage bench composites --size WxH`)")


def heads(options):
    check_cache(options.cache)
    size, cameras, frames, _ = rig(options.cache)
    for source, base in pairs():
        folder = options.out / f"{source}-{base}"
        try:
            folder.mkdir(parents=True, exist_ok=True)
        except OSError as error:
            fail(f"cannot make {folder}: {error.strerror}")
        forget_trained(folder)
        for colour, tone, report in (("semantic", "base", "toned.json"),
                                     ("off", "source", "own-tone.json")):
            recipe = folder / f"{colour}.toml"
            recipe.write_text(toned_recipe(source, base, colour))
            truth = folder / f"truth-{tone}"
            run([options.visage, "capture", "--recipe", str(recipe), "--tone", tone,
                 "--seams", "hard", "--size", size, "--cameras", cameras, "--frames", frames,
                 "-o", str(truth)], f"capture {source} on {base}")
            write_atomically(folder / report, evaluate(options.visage, options.cache, recipe,
                                                       truth, f"{source} on {base}"))
        toned = read_json(folder / "toned.json")["quality"]["psnr_db"]
        own = read_json(folder / "own-tone.json")["quality"]["psnr_db"]
        print(f"{source} in {base}'s tone: {toned:.2f} dB (in its own tone {own:.2f} dB)")


def trained(options):
    """Each pair's source trained on its toned head's truth, measured there."""
    check_cache(options.cache)
    iterations = rig(options.cache)[3]
    for source, base in pairs():
        folder = options.heads / f"{source}-{base}"
        truth, recipe = folder / "truth-base", folder / "off.toml"
        if not all(p.is_file() for p in (truth / "transforms_train.json", recipe,
                                          folder / "toned.json")):
            fail(f"{folder} holds no toned head (run `heads --out {options.heads}` first)")
        avatar, report = folder / "trained", folder / "trained.json"
        # The old report goes first: a killed run leaves the pair unmeasured,
        # and `combine` leaves the column out rather than mix in an old figure.
        report.unlink(missing_ok=True)
        if not finished(avatar, iterations):
            # Trained aside and moved into place, so a killed run leaves no
            # half-trained avatar that a later run would take as finished.
            partial = folder / "trained.partial"
            shutil.rmtree(partial, ignore_errors=True)
            print(f"training {source} in {base}'s tone ({iterations} iterations)…", flush=True)
            run([options.visage, "train", str(truth), "-o", str(partial), "--iterations",
                 iterations, "--seed", "1", "--checkpoint-every", "0"],
                f"train {source} in {base}'s tone")
            shutil.rmtree(avatar, ignore_errors=True)
            try:
                partial.rename(avatar)
            except OSError as error:
                fail(f"cannot move {partial} to {avatar}: {error.strerror}")
        # The two people the toned head shows, the source's place taken by
        # the one trained in the base's tone.
        database = folder / "trained-db"
        try:
            shutil.rmtree(database, ignore_errors=True)
            database.mkdir()
            (database / source).symlink_to(avatar.resolve())
            (database / base).symlink_to((options.cache / base).resolve())
        except OSError as error:
            fail(f"cannot make {database}: {error.strerror}")
        write_atomically(report, evaluate(options.visage, database, recipe, truth,
                                          f"{source} trained in {base}'s tone"))
        psnr = read_json(report)["quality"]["psnr_db"]
        toned = read_json(folder / "toned.json")["quality"]["psnr_db"]
        print(f"{source} trained in {base}'s tone: {psnr:.2f} dB (transferred to it: {toned:.2f} dB)")


def finished(avatar, iterations):
    """Whether `avatar` is a whole one trained as `trained` trains (the
    cache's iterations, seed 1): one trained otherwise is made again."""
    try:
        made = json.loads((avatar / "training.json").read_text())
    except (OSError, json.JSONDecodeError):
        return False
    return ((avatar / "point_cloud.ply").is_file()
            and str(made.get("iterations")) == iterations and made.get("seed") == 1)


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


def recipe_row(recipe, base, heads_folder, reports):
    """PSNR, ceiling and, per head report of `reports`, its reference (the
    toned reference, the own-tone control, the toned ceiling) of one recipe,
    each a squared error over the recipe's own band and interior pixels."""
    totals = [0.0] * (2 + len(reports))
    pixels_in_all = 0
    for region in recipe["report"]["regions"]:
        name, source = region["region"], region["source"]
        references = None
        if source != base:
            folder = heads_folder / f"{source}-{base}"
            references = [head_regions(folder, report).get(name) for report in reports]
            for report, reference in zip(reports, references):
                if reference is None:
                    fail(f"{folder / report} shows no {name}: its reference would be guessed")
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
            for k, psnr in enumerate([figures["psnr_db"], ceiling]
                                     + (references or [ceiling] * len(reports))):
                totals[k] += squared(psnr, pixels)
            pixels_in_all += pixels
    if not pixels_in_all:
        fail(f"{recipe['recipe']} has no region with pixels")
    return [-10 * math.log10(t / pixels_in_all) for t in totals]


def combine(options):
    run_json = read_json(options.run)
    if not isinstance(run_json, dict) or not run_json.get("recipes"):
        fail(f"{options.run} is not the JSON of `visage bench composites` (no recipes)")
    bases = {p.stem: tomllib.loads(p.read_text())["base"] for p in RECIPES.glob("*.toml")}
    # The toned ceiling only where `trained` has measured every pair: a
    # column over some of them would mix two kinds of figure.
    measured = [(options.heads / f"{s}-{b}" / "trained.json").is_file() for s, b in pairs()]
    if any(measured) and not all(measured):
        print(f"toned-reference: toned ceiling left out: `trained` has measured "
              f"{sum(measured)} of {len(measured)} pairs in {options.heads}", file=sys.stderr)
    reports = ["toned.json", "own-tone.json"] + (["trained.json"] if all(measured) else [])
    rows = []
    for recipe in run_json["recipes"]:
        base = bases.get(recipe["recipe"])
        if base is None:
            fail(f"{recipe['recipe']} is not one of {RECIPES}'s recipes")
        rows.append((recipe["recipe"], recipe_row(recipe, base, options.heads, reports)))
    means = [sum(row[k] for _, row in rows) / len(rows) for k in range(len(rows[0][1]))]
    titles = ["PSNR", "ceiling", "toned", "own tone", "toned ceiling"][:len(means)]
    print(f"{'recipe':24}" + "".join(f"{t:>{max(8, len(t) + 2)}}" for t in titles))
    for name, row in rows + [("mean", means)]:
        print(f"{name:24}" + "".join(f"{v:{max(8, len(t) + 2)}.2f}" for t, v in zip(titles, row)))
    print("dB over each recipe's own pixels; toned: each swapped source's region as its toned "
          "head shows it, the base's as its ceiling; own tone: the same heads with colour off "
          "against their own tone's truth (what the heads cost before any transfer)"
          + ("; toned ceiling: each swapped source's region as the source trained in the "
             "base's tone shows it" if len(means) > 4 else ""))


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    commands = parser.add_subparsers(dest="command", required=True)
    make = commands.add_parser("heads", help="capture and measure each pair's toned head")
    make.add_argument("--cache", type=pathlib.Path, required=True)
    make.add_argument("--out", type=pathlib.Path, required=True)
    make.add_argument("--visage", default=str(REPOSITORY / "target" / "release" / "visage"))
    train = commands.add_parser("trained", help="train each pair's source in the base's tone")
    train.add_argument("--cache", type=pathlib.Path, required=True)
    train.add_argument("--heads", type=pathlib.Path, required=True)
    train.add_argument("--visage", default=str(REPOSITORY / "target" / "release" / "visage"))
    join = commands.add_parser("combine", help="per recipe: PSNR beside its references")
    join.add_argument("run", type=pathlib.Path)
    join.add_argument("heads", type=pathlib.Path)
    options = parser.parse_args()
    try:
        {"heads": heads, "trained": trained, "combine": combine}[options.command](options)
    except KeyboardInterrupt:
        fail("interrupted (finished pairs are kept; run it again to go on)")


if __name__ == "__main__":
    main()
