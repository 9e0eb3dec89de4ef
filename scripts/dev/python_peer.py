#!/usr/bin/env python3
"""The Python pipeline a user would assemble instead of lidar-noise, timed end to end.

usage: python_peer.py CAPTURE OUT_DIR [RATE_MM_H]

velodyne_decoder (HDL-32E, bundled calibration) -> numpy noise as configs/paper.toml
describes it (rings 15-19 occluded; Goodin rain: ideal power kappa * rho / R^2 with rho
= reflectivity / 100 and kappa from a 10 % target at 100 m returning the 0.1 %
threshold, two-way extinction exp(-2 alpha R) with alpha = 0.01 rate^0.6, Gaussian range
noise sigma = 0.02 R (1 - exp(-rate))^2, detection threshold 0.1 %, minimum range 0.9 m)
-> Patchwork++ ground removal (pypatchworkpp, sensor height 1.9 m, its defaults
otherwise) -> Open3D DBSCAN (eps 0.5 m, 1 minimum point: a single-linkage cut at 0.5 m)
-> one binary PLY per frame with plyfile (x y z intensity ring ground cluster).

Prints two lines: frames, seconds (wall, from the first frame to the last, after imports)
and frames per second; then the steady state, the median time of one full frame (frames
of at least 90 % of the median return count: the capture's trailing half frame is not
one) and its frames per second, which is what a long capture runs at. Same random seed
every run. Nothing here is tuned to be slow: every step is one
vectorised call of the library a user would pick.
"""
import os
import sys
import time

import numpy as np


def main():
    capture, out = sys.argv[1], sys.argv[2]
    rate = float(sys.argv[3]) if len(sys.argv) > 3 else 7.0
    import open3d as o3d
    import plyfile
    import pypatchworkpp
    import velodyne_decoder as vd

    os.makedirs(out, exist_ok=True)
    o3d.utility.set_verbosity_level(o3d.utility.VerbosityLevel.Error)
    params = pypatchworkpp.Parameters()
    params.sensor_height = 1.9
    params.verbose = False
    patchwork = pypatchworkpp.patchworkpp(params)
    rng = np.random.default_rng(42)
    threshold = 0.001
    kappa = threshold * 100.0**2 / 0.10
    alpha = 0.01 * rate**0.6
    sigma_k = 0.02 * (1.0 - np.exp(-rate)) ** 2

    t0 = time.perf_counter()
    frames = 0
    # (returns, seconds) of each frame, decoding included: the steady state's inputs.
    per_frame = []
    t_frame = t0
    config = vd.Config(model=vd.Model.HDL32E)
    for _stamp, pts in vd.read_pcap(capture, config):
        xyz = pts[:, :3].astype(np.float64)
        intensity = pts[:, 3]
        ring = pts[:, 6].astype(np.int32)
        r = np.linalg.norm(xyz, axis=1)
        keep = ~np.isin(ring, [15, 16, 17, 18, 19])
        rho = np.clip(intensity / 100.0, 0.005, 1.0)
        power = np.minimum(kappa * rho / np.maximum(r, 1e-6) ** 2, 1.0)
        power *= np.exp(-2.0 * alpha * r)
        r_noisy = r + rng.normal(0.0, 1.0, r.shape) * sigma_k * r
        keep &= (power >= threshold) & (r_noisy >= 0.9)
        scale = (r_noisy / np.maximum(r, 1e-9))[:, None]
        cloud = (xyz * scale)[keep]
        # Intensity as the fourth column lets Patchwork++ run its reflected-noise removal.
        with_intensity = np.c_[cloud, intensity[keep].astype(np.float64) / 255.0]
        patchwork.estimateGround(np.ascontiguousarray(with_intensity, dtype=np.float64))
        ground_idx = patchwork.getGroundIndices()
        ground = np.zeros(len(cloud), dtype=np.uint8)
        ground[ground_idx] = 1
        rest = cloud[ground == 0]
        pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(rest))
        labels = np.asarray(pcd.cluster_dbscan(eps=0.5, min_points=1))
        cluster = np.full(len(cloud), -1, dtype=np.int32)
        cluster[ground == 0] = labels
        vertex = np.empty(
            len(cloud),
            dtype=[
                ("x", "f4"),
                ("y", "f4"),
                ("z", "f4"),
                ("intensity", "u1"),
                ("ring", "u1"),
                ("ground", "u1"),
                ("cluster", "i4"),
            ],
        )
        vertex["x"], vertex["y"], vertex["z"] = cloud[:, 0], cloud[:, 1], cloud[:, 2]
        vertex["intensity"] = intensity[keep].astype(np.uint8)
        vertex["ring"] = ring[keep].astype(np.uint8)
        vertex["ground"] = ground
        vertex["cluster"] = cluster
        el = plyfile.PlyElement.describe(vertex, "vertex")
        plyfile.PlyData([el]).write(os.path.join(out, f"frame_{frames:05d}.ply"))
        frames += 1
        now = time.perf_counter()
        per_frame.append((len(pts), now - t_frame))
        t_frame = now
    seconds = time.perf_counter() - t0
    print(f"python peer: {frames} frames in {seconds:.3f} s, {frames / seconds:.2f} frames/s")
    typical = np.median([n for n, _ in per_frame])
    full = [s for n, s in per_frame if n >= 0.9 * typical]
    median = float(np.median(full))
    print(
        f"python peer steady state: {median * 1e3:.1f} ms per full frame "
        f"(median of {len(full)} of {frames} frames), {1 / median:.2f} frames/s"
    )


if __name__ == "__main__":
    main()
