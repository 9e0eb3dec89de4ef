#!/usr/bin/env python3
"""Times what a user would pick instead of lidar-noise, on the shared HDL-32E capture.

usage: bench_compare.py CAPTURE FRAME_PLY
  CAPTURE    ../shared/data/hdl32e/monterey.pcap
  FRAME_PLY  a frame written by `lidar-noise run -c configs/clear.toml --frames 1`
             (its `ground` field selects the clustering input)

Prints one line per tool: velodyne_decoder's decode rate, and scikit-learn's (and, when
installed, Open3D's) DBSCAN with eps 0.5 m and 1 minimum point, which equals a
single-linkage distance cut at 0.5 m.
"""
import sys
import time

import numpy as np


def best_of(fn, repeats):
    best = float("inf")
    out = None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def main():
    capture, ply_path = sys.argv[1], sys.argv[2]
    import velodyne_decoder as vd

    config = vd.Config(model=vd.Model.HDL32E, min_range=0.0)

    def decode():
        n = 0
        for _stamp, points in vd.read_pcap(capture, config):
            n += len(points)
        return n

    secs, n = best_of(decode, 3)
    print(f"velodyne_decoder {vd.__version__}: {n} returns in {secs*1e3:.1f} ms = {n/secs/1e6:.1f} M returns/s")

    from plyfile import PlyData

    v = PlyData.read(ply_path)["vertex"]
    mask = np.asarray(v["ground"]) == 0
    pts = np.stack([np.asarray(v[c])[mask] for c in "xyz"], axis=1).astype(np.float64)
    from sklearn.cluster import DBSCAN

    secs, labels = best_of(lambda: DBSCAN(eps=0.5, min_samples=1).fit_predict(pts), 5)
    print(f"scikit-learn DBSCAN: {len(pts)} points, {labels.max()+1} clusters in {secs*1e3:.1f} ms")
    try:
        import open3d as o3d
    except ImportError:
        print("open3d: not installed (WITH_OPEN3D=1 installs it)")
        return
    pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts))
    secs, labels = best_of(lambda: np.asarray(pc.cluster_dbscan(eps=0.5, min_points=1)), 5)
    print(f"Open3D cluster_dbscan: {len(pts)} points, {labels.max()+1} clusters in {secs*1e3:.1f} ms")


if __name__ == "__main__":
    main()
