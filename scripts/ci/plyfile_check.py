#!/usr/bin/env python3
"""Checks lidar-noise PLY files with an independent reader (the `plyfile` package).

Usage: python3 scripts/ci/plyfile_check.py FILE.ply [FILE.ply ...]

For each file: loads it with plyfile, requires an element `vertex` with at least the
properties below and these dtypes, no 64-bit integer property anywhere, at least one
point, and finite values in every float property. Prints one line per file and exits
non-zero if any file fails.

Needs: pip install plyfile numpy

Open3D compatibility (documented, not checked here, Open3D is not installed): Open3D's
PLY reader (`o3d.io.read_point_cloud` / `o3d.t.io.read_point_cloud`) looks for element
`vertex` with float/double `x y z`; the tensor API also exposes the other scalar
properties as attributes (`intensity`, `ring`, ...). Both reject or mishandle 64-bit
integer properties, which is why the writer never emits them.
"""

import sys

import numpy as np

try:
    from plyfile import PlyData
except ImportError:  # pragma: no cover - message for the user
    sys.exit("plyfile is not installed: pip install plyfile numpy")

REQUIRED = [
    ("x", "f4"),
    ("y", "f4"),
    ("z", "f4"),
    ("intensity", "u1"),
    ("ring", "u1"),
    ("laser", "u1"),
    ("azimuth", "f4"),
    ("range", "f4"),
    ("time", "f4"),
]
OPTIONAL = {
    "range_clean": "f4",
    "power": "f4",
    "fate": "u1",
    "cause": "u1",
    "ground": "u1",
    "cluster": "i4",
}


def same_type(got, want):
    """True when dtype `got` has the kind and size of `want` ('f4', 'u1', ...), any byte order."""
    want = np.dtype(want)
    return got.kind == want.kind and got.itemsize == want.itemsize


def check(path):
    """Returns a list of problems with the file (empty when it is fine) and a summary."""
    problems = []
    try:
        ply = PlyData.read(path)
    except Exception as e:  # plyfile raises several exception types
        return [f"unreadable: {e}"], ""
    for element in ply.elements:
        for prop in element.properties:
            dt = np.dtype(element[prop.name].dtype)
            if dt.kind in "iu" and dt.itemsize == 8:
                problems.append(f"{element.name}.{prop.name} is a 64-bit integer")
    if "vertex" not in [e.name for e in ply.elements]:
        return problems + ["no element 'vertex'"], ""
    vertex = ply["vertex"]
    data = vertex.data
    names = data.dtype.names or ()
    for name, want in REQUIRED:
        if name not in names:
            problems.append(f"missing property {name}")
            continue
        if not same_type(data.dtype[name], want):
            problems.append(f"property {name} is {data.dtype[name].str}, expected {want}")
    for name, want in OPTIONAL.items():
        if name in names and not same_type(data.dtype[name], want):
            problems.append(f"optional property {name} is {data.dtype[name].str}, expected {want}")
    if len(data) == 0:
        problems.append("no points")
    for name in names:
        column = data[name]
        if column.dtype.kind == "f" and not np.all(np.isfinite(column)):
            bad = int(np.count_nonzero(~np.isfinite(column)))
            problems.append(f"{bad} non-finite value(s) in {name}")
    fmt = "ascii" if ply.text else ("binary_little_endian" if ply.byte_order == "<" else "binary_big_endian")
    summary = f"{len(data)} points, {len(names)} properties ({' '.join(names)}), {fmt}"
    return problems, summary


def main(argv):
    if len(argv) < 2:
        print(__doc__.strip().splitlines()[2], file=sys.stderr)
        return 2
    failed = 0
    for path in argv[1:]:
        problems, summary = check(path)
        if problems:
            failed += 1
            print(f"FAIL {path}: {'; '.join(problems)}")
        else:
            print(f"ok   {path}: {summary}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
