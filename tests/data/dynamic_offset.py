"""Per-frame offsets written the way a tracker writes them: numpy's own
np.load / np.savez (float32), as VHAP's exporter writes `dynamic_offset`
into a GaussianAvatars flame_param.npz and GaussianAvatars' loader reads it.

    python3 tests/data/dynamic_offset.py write IN.npz OUT.npz
        copies IN, sets dynamic_offset[t, i] = pattern(t, i) for every frame
        and vertex, and puts frame 1 at rest (zero rotation, neck, jaw, eyes
        and translation) so its posing is the identity;
    python3 tests/data/dynamic_offset.py compare A.npz B.npz
        checks B's dynamic_offset equals A's (float32, bit for bit) and
        prints one JSON line: frames, vertices, largest |offset|.

Needs only numpy (Debian: python3-numpy, which .ci/setup installs).
"""
import json
import sys

import numpy as np


def pattern(frames, vertices):
    t = np.arange(frames, dtype=np.float64)[:, None]
    i = np.arange(vertices, dtype=np.float64)[None, :]
    x = 1e-3 * np.sin(0.7 * t + 0.013 * i)
    y = 5e-4 * np.cos(0.3 * t - 0.021 * i)
    z = 2e-4 * (t + 1.0) * np.ones_like(i)
    return np.stack([x, y, z], axis=-1).astype(np.float32)


def load(path):
    with np.load(path) as npz:
        return {k: npz[k] for k in npz.files}


if sys.argv[1] == "write":
    params = load(sys.argv[2])
    frames = params["expr"].shape[0]
    vertices = params["static_offset"].shape[1]
    params["dynamic_offset"] = pattern(frames, vertices)
    if frames > 1:
        for key in ("rotation", "neck_pose", "jaw_pose", "eyes_pose", "translation"):
            params[key][1] = 0.0
    np.savez(sys.argv[3], **params)
elif sys.argv[1] == "compare":
    a, b = load(sys.argv[2])["dynamic_offset"], load(sys.argv[3])["dynamic_offset"]
    if b.dtype != np.float32 or a.shape != b.shape:
        sys.exit("dynamic_offset: %s %s, expected float32 %s" % (b.dtype, b.shape, a.shape))
    if not np.array_equal(a, b):
        sys.exit("dynamic_offset differs by up to %g" % float(np.abs(a - b).max()))
    print(json.dumps({"frames": a.shape[0], "vertices": a.shape[1],
                      "largest": float(np.abs(b).max())}))
else:
    sys.exit(__doc__)
