"""Writes a small 3DGS scene as an INRIA PLY with plyfile (the library the 3DGS
trainers use) and converts it to antimatter15's .splat with ply2splat 0.6.0
(a converter others wrote), so visage's .splat reader and writer are tested
against files it did not make. Run: pip install plyfile numpy ply2splat==0.6.0;
python3 tests/data/splat/make_splat.py. The outputs are committed.

- ring.ply: 200 Gaussians on a ring, SH degree 0, random scales, rotations
  (not normalised) and opacities, binary little endian.
- ring.splat: ply2splat's conversion in file order (sort=False).
- ring3.ply: the same ring with SH degree 3 (45 f_rest properties).

make_compressed.sh then turns ring.ply and ring3.ply into SuperSplat's
compressed PLY with PlayCanvas's splat-transform.
"""
import os

import numpy as np
from plyfile import PlyData, PlyElement
import ply2splat

here = os.path.dirname(os.path.abspath(__file__))
rng = np.random.RandomState(7)
n = 200
t = np.linspace(0, 2 * np.pi, n, endpoint=False)
props = [(name, "f4") for name in
         ["x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2", "opacity",
          "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"]]
v = np.zeros(n, dtype=props)
v["x"], v["y"], v["z"] = 2 * np.cos(t), 2 * np.sin(t), rng.uniform(-0.2, 0.2, n)
v["f_dc_0"], v["f_dc_1"], v["f_dc_2"] = (rng.uniform(-1.5, 1.5, n) for _ in range(3))
v["opacity"] = rng.uniform(-4, 4, n)
v["scale_0"], v["scale_1"], v["scale_2"] = (rng.uniform(-4, -1.5, n) for _ in range(3))
v["rot_0"], v["rot_1"], v["rot_2"], v["rot_3"] = (rng.uniform(-1, 1, n) for _ in range(4))
ply_path = os.path.join(here, "ring.ply")
PlyData([PlyElement.describe(v, "vertex")], byte_order="<").write(ply_path)
count = ply2splat.convert(ply_path, os.path.join(here, "ring.splat"), sort=False)
print("wrote ring.ply and ring.splat,", count, "splats")

rest = [("f_rest_%d" % k, "f4") for k in range(45)]
props3 = props[:9] + rest + props[9:]
v3 = np.zeros(n, dtype=props3)
for name, _ in props:
    v3[name] = v[name]
for name, _ in rest:
    v3[name] = rng.uniform(-0.3, 0.3, n)
PlyData([PlyElement.describe(v3, "vertex")], byte_order="<").write(os.path.join(here, "ring3.ply"))
print("wrote ring3.ply")
