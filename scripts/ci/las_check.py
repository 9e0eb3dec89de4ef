#!/usr/bin/env python3
"""Checks lidar-noise LAS/LAZ files with an independent reader (laspy, lazrs for LAZ).

Usage: python3 scripts/ci/las_check.py FILE.las|FILE.laz [...]

For each file: opens it with laspy, requires LAS 1.4 point format 6, scale 0.001 m,
at least one point, the extra-bytes dimensions below with these types (the optional
ones as written by `run`), plausible values in every dimension (finite coordinates
within the sensor's range, rings and lasers 0-31, azimuth in [0, 360), classes 0, 1, 2
or 7, fate 0-5 with class 7 and the Withheld flag exactly where fate is 1-3 (dropped),
the Synthetic flag exactly where fate is 4-5 (spurious echoes), class 2 exactly where
ground = 1 among reported returns, cluster >= -1, finite GPS time).
Prints one line per file and exits non-zero if any file fails.

Needs: pip install laspy lazrs numpy
"""

import sys

import numpy as np

try:
    import laspy
except ImportError:  # pragma: no cover - message for the user
    sys.exit("laspy is not installed: pip install laspy lazrs numpy")

REQUIRED = {"ring": "u1", "laser": "u1", "azimuth": "f4", "range": "f4", "time": "f4"}
OPTIONAL = {
    "range_clean": "f4",
    "power": "f4",
    "ground": "u1",
    "fate": "u1",
    "cause": "u1",
    "cluster": "i4",
}
MAX_RANGE_M = 150.0


def check(path):
    """Returns a list of problems with the file (empty when it is fine) and a summary."""
    problems = []
    try:
        las = laspy.read(path)
    except Exception as e:  # laspy raises several exception types
        return [f"cannot read: {e}"], ""
    h = las.header
    if (h.version.major, h.version.minor) != (1, 4):
        problems.append(f"version {h.version}, expected 1.4")
    if las.point_format.id != 6:
        problems.append(f"point format {las.point_format.id}, expected 6")
    if not np.allclose(h.scales, 0.001):
        problems.append(f"scales {h.scales}, expected 0.001")
    n = len(las.points)
    if n == 0:
        problems.append("no points")
        return problems, ""
    extra = {d.name: d for d in las.point_format.extra_dimensions}
    for name, dtype in list(REQUIRED.items()) + list(OPTIONAL.items()):
        if name not in extra:
            if name in REQUIRED:
                problems.append(f"extra dimension {name} missing")
            continue
        got = np.asarray(las[name]).dtype
        if got != np.dtype(dtype):
            problems.append(f"{name} has type {got}, expected {dtype}")
    for axis in ("x", "y", "z"):
        v = np.asarray(las[axis])
        if not np.all(np.isfinite(v)) or np.abs(v).max() > MAX_RANGE_M:
            problems.append(f"{axis} outside +-{MAX_RANGE_M} m")
    t = np.asarray(las.gps_time)
    if not np.all(np.isfinite(t)) or t.min() < 0:
        problems.append("gps_time not finite and non-negative")
    if np.asarray(las.intensity).max() > 255:
        problems.append("intensity above 255")
    for name in ("ring", "laser"):
        if name in extra and np.asarray(las[name]).max() > 31:
            problems.append(f"{name} above 31")
    az = np.asarray(las["azimuth"]) if "azimuth" in extra else np.zeros(1)
    if az.min() < 0 or az.max() >= 360:
        problems.append("azimuth outside [0, 360)")
    for name in ("range", "range_clean"):
        if name in extra:
            r = np.asarray(las[name])
            if not np.all(np.isfinite(r)) or r.min() < 0 or r.max() > MAX_RANGE_M:
                problems.append(f"{name} outside [0, {MAX_RANGE_M}] m")
    if "power" in extra:
        p = np.asarray(las["power"])
        if not np.all(np.isfinite(p)) or p.min() < 0 or p.max() > 1:
            problems.append("power outside [0, 1]")
    cls = np.asarray(las.classification)
    if not np.isin(cls, [0, 1, 2, 7]).all():
        problems.append(f"classes {sorted(set(cls.tolist()))}, expected among 0 1 2 7")
    if "fate" in extra:
        fate = np.asarray(las["fate"])
        if fate.max() > 5:
            problems.append("fate above 5")
        dropped = (fate >= 1) & (fate <= 3)
        if not np.array_equal(dropped, cls == 7):
            problems.append("class 7 is not exactly the dropped returns (fate 1-3)")
        if not np.array_equal(dropped, np.asarray(las.withheld, dtype=bool)):
            problems.append("the Withheld flag is not exactly the dropped returns (fate 1-3)")
        if not np.array_equal(fate >= 4, np.asarray(las.synthetic, dtype=bool)):
            problems.append("the Synthetic flag is not exactly the spurious echoes (fate 4-5)")
    if "ground" in extra:
        g = np.asarray(las["ground"])
        reported = ~np.isin(cls, [7])
        if not np.array_equal((g == 1)[reported], (cls == 2)[reported]):
            problems.append("class 2 is not exactly the reported returns with ground = 1")
    if "cluster" in extra and np.asarray(las["cluster"]).min() < -1:
        problems.append("cluster below -1")
    summary = f"{n} points, {len(extra)} extra dimensions ({' '.join(extra)})"
    return problems, summary


def main(paths):
    if not paths:
        sys.exit(__doc__)
    failed = 0
    for path in paths:
        problems, summary = check(path)
        if problems:
            failed += 1
            print(f"FAIL {path}: {'; '.join(problems)}")
        else:
            print(f"ok   {path}: {summary}")
    if failed:
        sys.exit(f"{failed} of {len(paths)} files failed the laspy check")


if __name__ == "__main__":
    main(sys.argv[1:])
