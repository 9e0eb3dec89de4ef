#!/usr/bin/env python3
"""Cross-checks lidar-noise clustering against SciPy.

Usage: scipy_check.py PATH/TO/cluster_cli

Generates seeded clouds (blobs plus uniform noise, float32 values so both sides see the
same numbers), runs the example binary and compares with
scipy.cluster.hierarchy.fcluster(linkage(X, 'single'), t, criterion) for the distance,
inconsistent (depth 2) and maxclust criteria: partitions must be identical. The complete
merge tree must equal SciPy's linkage matrix (ids, heights, counts); a tree bounded by
max_edge must have exactly SciPy's heights up to the bound. Exits non-zero on a mismatch and
prints a summary line.
"""
import csv
import os
import subprocess
import sys
import tempfile

import numpy as np
from scipy.cluster.hierarchy import fcluster, linkage


def cloud(rng, n):
    extent = rng.uniform(3.0, 20.0)
    n_blobs = rng.integers(1, 10)
    centers = rng.uniform(-extent, extent, size=(n_blobs, 3))
    centers[:, 2] = rng.uniform(-2.0, 2.0, size=n_blobs)
    spread = rng.uniform(0.1, 1.2, size=n_blobs)
    n_noise = int(n * rng.uniform(0.0, 0.4))
    which = rng.integers(0, n_blobs, size=n - n_noise)
    blobs = centers[which] + rng.normal(size=(n - n_noise, 3)) * spread[which, None]
    noise = rng.uniform(-extent, extent, size=(n_noise, 3))
    pts = np.vstack([blobs, noise]).astype(np.float32)
    return pts[rng.permutation(n)]


def canonical(labels):
    first = {}
    return [first.setdefault(l, i) for i, l in enumerate(labels)]


def read_labels(path):
    with open(path) as f:
        rows = list(csv.reader(f))
    assert rows[0] == ["label"], rows[0]
    return [int(r[0]) for r in rows[1:]]


def read_linkage(path):
    with open(path) as f:
        rows = list(csv.reader(f))
    assert rows[0] == ["cluster_a", "cluster_b", "distance", "count"], rows[0]
    return np.array([[float(v) for v in r] for r in rows[1:]]).reshape(-1, 4)


def run(binary, pts_csv, tmp, cut, t, max_edge="inf"):
    labels = os.path.join(tmp, "labels.csv")
    link = os.path.join(tmp, "linkage.csv")
    subprocess.run(
        [binary, pts_csv, "--cut", cut, "--t", repr(t), "--max-edge", max_edge,
         "--labels", labels, "--linkage", link],
        check=True, stderr=subprocess.DEVNULL,
    )
    return read_labels(labels), read_linkage(link)


def main():
    if len(sys.argv) != 2:
        print(__doc__)
        return 2
    binary = sys.argv[1]
    failures = []
    checks = 0
    with tempfile.TemporaryDirectory() as tmp:
        for seed in range(12):
            rng = np.random.default_rng(seed)
            n = 2000 if seed % 4 == 0 else int(rng.integers(10, 2000))
            pts = cloud(rng, n)
            pts_csv = os.path.join(tmp, "points.csv")
            with open(pts_csv, "w") as f:
                f.write("x,y,z\n")
                for p in pts:
                    # 9 significant digits round-trip a float32 exactly.
                    f.write("%.9g,%.9g,%.9g\n" % tuple(float(v) for v in p))
            X = pts.astype(np.float64)
            Z = linkage(X, "single")

            def compare(name, ours, theirs):
                nonlocal checks
                checks += 1
                if canonical(ours) != canonical(list(theirs)):
                    failures.append(f"seed {seed} n {n}: {name}")

            for t in (0.2, 0.5, 1.0):
                ours, z_ours = run(binary, pts_csv, tmp, "distance", t)
                compare(f"distance {t}", ours, fcluster(Z, t, "distance"))
            checks += 1
            if z_ours.shape != Z.shape or not np.array_equal(z_ours, Z):
                diff = "shape" if z_ours.shape != Z.shape else np.max(np.abs(z_ours - Z))
                failures.append(f"seed {seed} n {n}: complete linkage differs ({diff})")
            for t in (0.8, 1.0, 1.15, 1.5):
                ours, _ = run(binary, pts_csv, tmp, "inconsistent", t)
                compare(f"inconsistent {t}", ours, fcluster(Z, t, "inconsistent", depth=2))
            for k in (1, 2, 5, 17, max(1, n // 3), n - 1, n):
                ours, _ = run(binary, pts_csv, tmp, "maxclust", float(k))
                compare(f"maxclust {k}", ours, fcluster(Z, k, "maxclust"))
            bound = 0.7
            _, z_b = run(binary, pts_csv, tmp, "distance", 0.5, repr(bound))
            checks += 1
            want = Z[Z[:, 2] <= bound, 2]
            if not np.array_equal(np.sort(z_b[:, 2]), np.sort(want)):
                failures.append(f"seed {seed} n {n}: bounded linkage heights differ")
    for f in failures:
        print("MISMATCH", f)
    status = "FAIL" if failures else "OK"
    print(f"scipy_check: {status}: {checks - len(failures)}/{checks} checks agree "
          f"(12 clouds up to 2000 points)")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
