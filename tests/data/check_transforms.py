"""Reads a dataset the way GaussianAvatars' dataset reader does
(scene/dataset_readers.py: readCamerasFromTransforms, readMeshesFromTransforms)
and checks it would load there: per frame `file_path` (".png" appended when it
is missing), `transform_matrix` turned from the NeRF/Blender convention to
COLMAP's (columns 1-2 negated) and inverted, the field of view from
`camera_angle_x` (a frame's own value first), `timestep_index`, `camera_id`,
and every `flame_param_path` loaded with numpy. Prints one JSON line: the
frame and timestep counts per split and, for the first training frame, where
GaussianAvatars' camera puts the world point given on the command line.

    python3 tests/data/check_transforms.py DATASET X Y Z

Needs only numpy.
"""
import json
import math
import os
import sys

import numpy as np


def fail(message):
    sys.exit("check_transforms: " + message)


root = sys.argv[1]
point = np.array([float(v) for v in sys.argv[2:5]] + [1.0])
summary = {}
first = None
for split in ("train", "val", "test"):
    path = os.path.join(root, "transforms_%s.json" % split)
    if not os.path.exists(path):
        continue
    with open(path) as f:
        contents = json.load(f)
    fovx_top = contents.get("camera_angle_x")
    timesteps = set()
    for frame in contents["frames"]:
        file_path = frame["file_path"]
        if ".png" not in file_path:
            file_path += ".png"
        image = os.path.join(root, file_path)
        if not os.path.exists(image):
            fail("%s: image %s is missing" % (split, image))
        c2w = np.array(frame["transform_matrix"])
        c2w[:3, 1:3] *= -1
        w2c = np.linalg.inv(c2w)
        fovx = frame.get("camera_angle_x", fovx_top)
        if fovx is None:
            fail("%s: no camera_angle_x" % split)
        width, height = frame["w"], frame["h"]
        timestep = frame["timestep_index"]
        if "camera_id" not in frame:
            fail("%s: no camera_id (GaussianAvatars reads camera_index only with it)" % split)
        with np.load(os.path.join(root, frame["flame_param_path"])) as npz:
            for key in ("shape", "expr", "rotation", "neck_pose", "jaw_pose",
                        "eyes_pose", "translation", "static_offset"):
                if key not in npz.files:
                    fail("%s lacks %s" % (frame["flame_param_path"], key))
        timesteps.add(timestep)
        if first is None and split == "train":
            focal = width / (2 * math.tan(fovx / 2))
            p = w2c @ point
            first = [focal * p[0] / p[2] + width / 2, focal * p[1] / p[2] + height / 2]
    summary[split] = {"frames": len(contents["frames"]), "timesteps": len(timesteps)}
summary["first_train_pixel"] = first
print(json.dumps(summary))
