"""Shared helpers of the reference-implementation runners (no code of those projects).

The points: PLY files written by `lidar-noise convert` (frames 2-4 of monterey.pcap).
Mapping of our columns to the references' layouts is documented in each runner.
"""
import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "fidelity"))
from plyread import read_ply  # noqa: E402

import numpy as np  # noqa: E402


def load_points(paths):
    """x, y, z, intensity byte, ring of every return in the PLY files, as float arrays."""
    cols = {"x": [], "y": [], "z": [], "intensity": [], "ring": []}
    for p in sorted(paths):
        c = read_ply(p)
        for k in cols:
            cols[k].extend(c[k])
    return {k: np.asarray(v, dtype=np.float64) for k, v in cols.items()}


def reflectance(intensity):
    """The target reflectance our power model gives a calibrated-reflectivity byte
    (configs/clear.toml: 0..100 = percent, 101..255 retro-reflector = 1, floor 0.005)."""
    rho = np.where(intensity > 100, 1.0, intensity / 100.0)
    return np.maximum(rho, 0.005)


def quantiles(values, qs=(0.0, 0.05, 0.25, 0.5, 0.75, 0.95, 1.0)):
    """Named quantiles of a 1-D array (None when empty)."""
    if len(values) == 0:
        return None
    return {f"p{int(q * 100)}": round(float(np.quantile(values, q)), 3) for q in qs}
