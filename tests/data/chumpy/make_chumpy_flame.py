# -*- coding: utf-8 -*-
"""Writes FLAME-layout model and mask pickles with the real chumpy, numpy and
scipy, the way FLAME's own files were written (Python 2 cPickle), so visage's
tests read the object graph those libraries really produce — not our idea of it.

Run with Python 2.7, numpy 1.16.6, scipy 1.2.3 and chumpy 0.70, e.g.:

    pyenv install 2.7.18
    ~/.pyenv/versions/2.7.18/bin/python -m pip install numpy==1.16.6 scipy==1.2.3 chumpy==0.70
    ~/.pyenv/versions/2.7.18/bin/python tests/data/chumpy/make_chumpy_flame.py

The data are random (deterministic from a seed) with FLAME's array shapes and
dtypes; only the number of blend-shape components is reduced, for size. The
files are committed, so CI needs no Python 2.

- flame2023.pkl.gz: FLAME's 5023 vertices and 9976 triangles, protocol 2 (what
  `cPickle.dump(model, f, -1)` writes), `shapedirs` a chumpy Ch, J_regressor a
  scipy csc_matrix, the other fields numpy arrays (gzip-compressed for size; the
  pickle inside is byte for byte what cPickle wrote).
- FLAME_masks.pkl: the 14 mask names of FLAME_masks.pkl, int64 vertex ids,
  protocol 2.
- generic_model_p0.pkl / generic_masks_p0.pkl: a small model whose shapedirs,
  posedirs, J and weights are all Ch objects, pickled with protocol 0 (text), the
  older generic_model.pkl style; its masks carry the two 15-vertex lip rings.
"""
from __future__ import print_function

import gzip
import os
import sys

import cPickle as pickle
import numpy as np
import scipy.sparse as sp
import chumpy as ch

assert sys.version_info[0] == 2, "run with Python 2.7 (FLAME's files are Python 2 pickles)"
assert ch.__version__ == "0.70", ch.__version__

here = os.path.dirname(os.path.abspath(__file__))
rng = np.random.RandomState(20251123)

MASK_NAMES = ["eye_region", "neck", "left_eyeball", "right_eyeball", "right_ear",
              "right_eye_region", "forehead", "lips", "nose", "scalp", "boundary",
              "face", "left_ear", "left_eye_region"]
# FLAME's outer lip rings (upper, lower), from which GaussianAvatars builds teeth.
RING_UPPER = [1713, 1715, 1716, 1735, 1696, 1694, 1657, 3543, 2774, 2811, 2813, 2850, 2833, 2832, 2830]
RING_LOWER = [1576, 1577, 1773, 1774, 1795, 1802, 1865, 3503, 2948, 2905, 2898, 2881, 2880, 2713, 2712]


def quantised(shape, scale):
    """Random values on a coarse grid (so gzip can shrink the fixture)."""
    return rng.randint(-16, 17, size=shape).astype(np.float64) * (scale / 16.0)


def model_arrays(vertices, faces, components):
    v_template = quantised((vertices, 3), 0.1)
    f = rng.randint(0, vertices, size=(faces, 3)).astype(np.uint32)
    weights = rng.rand(vertices, 5)
    weights = np.round(weights / weights.sum(axis=1, keepdims=True), 3)
    regressor = np.zeros((5, vertices))
    for j in range(5):
        cols = rng.choice(vertices, 12, replace=False)
        regressor[j, cols] = 1.0 / 12
    kintree = np.array([[4294967295, 0, 1, 1, 1], [0, 1, 2, 3, 4]], dtype=np.int64)
    return {
        "v_template": v_template,
        "f": f,
        "shapedirs": quantised((vertices, 3, components), 1e-3),
        "posedirs": quantised((vertices, 3, 36), 1e-3),
        "weights": weights,
        "J_regressor": sp.csc_matrix(regressor),
        "kintree_table": kintree,
        "J": quantised((5, 3), 0.1),
        "bs_style": "lbs",
        "bs_type": "lrotmin",
    }


def masks(vertices, rings):
    out = {}
    for name in MASK_NAMES:
        out[name] = np.sort(rng.choice(vertices, vertices // 10, replace=False)).astype(np.int64)
    if rings is not None:
        out["lip_outside_ring_upper"] = np.array(rings[0], dtype=np.int64)
        out["lip_outside_ring_lower"] = np.array(rings[1], dtype=np.int64)
    return out


def write(name, obj, protocol, compress=False):
    data = pickle.dumps(obj, protocol)
    path = os.path.join(here, name)
    if compress:
        with open(path, "wb") as raw:
            # mtime fixed so the file is the same bytes on every run
            with gzip.GzipFile(filename="", mode="wb", fileobj=raw, mtime=0) as f:
                f.write(data)
    else:
        with open(path, "wb") as f:
            f.write(data)
    print("wrote", name, len(data), "bytes pickled")


# FLAME 2023 style: FLAME's counts, only shapedirs is chumpy, protocol 2.
flame = model_arrays(5023, 9976, 6)
flame["shapedirs"] = ch.array(flame["shapedirs"])
write("flame2023.pkl.gz", flame, 2, compress=True)
write("FLAME_masks.pkl", masks(5023, None), 2)

# generic_model.pkl style: more chumpy fields, protocol 0, a small mesh.
small = model_arrays(60, 90, 4)
for key in ("shapedirs", "posedirs", "J", "weights"):
    small[key] = ch.array(small[key])
rings = (list(range(0, 15)), list(range(15, 30)))
write("generic_model_p0.pkl", small, 0)
write("generic_masks_p0.pkl", masks(60, rings), 0)
