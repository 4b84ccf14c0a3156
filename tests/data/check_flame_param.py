"""Reads a flame_param.npz the way GaussianAvatars' FlameGaussianModel does and
checks that it would work there: every array loaded as it is (np.load, no
pickles), the key set and float32 dtypes its own saved files have, the shapes
its forward pass needs, and the per-frame indexing of select_mesh_by_timestep
(`x[[t]]` for expr, poses, translation and dynamic_offset). Prints one JSON
line with the frame and vertex counts; exits non-zero naming the first problem.

    python3 tests/data/check_flame_param.py AVATAR_DIR/flame_param.npz

Needs only numpy (Debian: python3-numpy, which .ci/setup installs).
"""
import json
import sys

import numpy as np

KEYS = {"shape", "expr", "rotation", "neck_pose", "jaw_pose", "eyes_pose",
        "translation", "static_offset", "dynamic_offset"}


def fail(message):
    sys.exit("check_flame_param: " + message)


with np.load(sys.argv[1]) as npz:  # allow_pickle=False, as for any plain array file
    flame_param = {k: npz[k] for k in npz.files}

if set(flame_param) != KEYS:
    fail("keys %s, expected %s" % (sorted(flame_param), sorted(KEYS)))
for key, value in flame_param.items():
    if value.dtype != np.float32:
        fail("%s is %s, GaussianAvatars saves float32" % (key, value.dtype))
    if not np.isfinite(value).all():
        fail("%s has NaN or infinite values" % key)

frames = flame_param["expr"].shape[0]
vertices = flame_param["static_offset"].shape[1]
want = {
    "shape": (300,),
    "expr": (frames, 100),
    "rotation": (frames, 3),
    "neck_pose": (frames, 3),
    "jaw_pose": (frames, 3),
    "translation": (frames, 3),
    "eyes_pose": (frames, 6),
    "static_offset": (1, vertices, 3),
    "dynamic_offset": (frames, vertices, 3),
}
for key, shape in want.items():
    if flame_param[key].shape != shape:
        fail("%s has shape %s, expected %s" % (key, flame_param[key].shape, shape))

# select_mesh_by_timestep: shape[None, ...] and x[[t]] for every frame.
if flame_param["shape"][None, ...].shape != (1, 300):
    fail("shape[None, ...] is not (1, 300)")
for t in range(frames):
    for key in ("expr", "rotation", "neck_pose", "jaw_pose", "eyes_pose", "translation"):
        if flame_param[key][[t]].shape != (1,) + want[key][1:]:
            fail("%s[[%d]] has the wrong shape" % (key, t))
    if flame_param["dynamic_offset"][[t]].shape != (1, vertices, 3):
        fail("dynamic_offset[[%d]] has the wrong shape" % t)

print(json.dumps({"frames": frames, "vertices": vertices,
                  "static_offset_max": float(np.abs(flame_param["static_offset"]).max())}))
