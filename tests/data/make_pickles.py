"""Writes small pickles with real numpy/scipy to check visage's safe reader
against the real thing (run: python3 tests/data/make_pickles.py; needs numpy and
scipy). The files are committed; visage's tests read them without Python.

chumpy does not install on modern numpy, so a stand-in class with chumpy's
module and name is pickled: the bytes are what chumpy's Ch pickles to (a
copy_reg reconstruction plus a state dict holding the array as 'x').
"""
import os
import pickle
import sys
import types

import numpy as np
import scipy.sparse

here = os.path.dirname(os.path.abspath(__file__))

chumpy = types.ModuleType("chumpy")
chumpy_ch = types.ModuleType("chumpy.ch")


class Ch(object):
    def __init__(self, x):
        self.x = x

    def __reduce_ex__(self, protocol):
        import copyreg
        return (copyreg._reconstructor, (Ch, object, None), {"x": self.x})


Ch.__module__ = "chumpy.ch"
chumpy_ch.Ch = Ch
sys.modules["chumpy"] = chumpy
sys.modules["chumpy.ch"] = chumpy_ch

v_template = np.arange(12, dtype=np.float64).reshape(4, 3) / 10
model = {
    "v_template": v_template,
    "f": np.array([[0, 1, 2], [0, 2, 3]], dtype=np.uint32),
    "shapedirs": Ch(np.arange(24, dtype=np.float32).reshape(4, 3, 2)),
    "J_regressor": scipy.sparse.csc_matrix(np.array([[0.5, 0.5, 0, 0], [0, 0, 1.0, 0]])),
    "fortran": np.asfortranarray(np.arange(6, dtype=np.int16).reshape(2, 3)),
    "big_endian": np.arange(3, dtype=">f8"),
    "rows": scipy.sparse.csr_matrix(np.array([[0, 2.0], [3.0, 0]])),
    "name": u"flame",
    "weights": [0.25, 0.75],
    "scalar": np.float64(2.5),
}
# Python shares memoised objects: one array under two keys is pickled once and
# referenced again, and big-endian arrays share one dtype object whose byte
# order is set (BUILD) after it was memoised.
shared = np.linspace(0.0, 1.0, 5)
model["shared_a"] = shared
model["shared_b"] = shared
model["big_a"] = np.arange(4, dtype=">f4") + 0.5
model["big_b"] = np.arange(3, dtype=">i8") * 1000
model["dirty"] = {"x", "y"}
for protocol in (2, 4, 5):
    with open(os.path.join(here, f"real-protocol{protocol}.pkl"), "wb") as f:
        pickle.dump(model, f, protocol=protocol)
print("wrote real-protocol{2,4,5}.pkl")
