#!/usr/bin/env python3
"""Cross-check of `lidar-noise run --pcap-out` with an independent decoder.

velodyne_decoder (pip) reads the noisy capture; its points must match what lidar-noise
decodes from the same file (`lidar-noise convert noisy.pcap --keep-partial`, PLY files
read with plyfile) and what the run kept (`summary.json`, totals.noise.returns_out, for
a run made with --keep-partial): the same point count, and point by point (both list
the returns in capture order: packet, block, laser) the same ring and the same range
within half the 2 mm quantum once velodyne_decoder's per-ring offset is taken out.

That offset: velodyne_decoder 3's HDL-32E geometry puts each laser's origin slightly off
the sensor's centre, so the norm of its xyz is the range minus a constant per ring (8.7
mm for ring 0 down to 1.0 mm for ring 31, the same on every capture). The check takes
the median difference per ring (it must be under 1 cm) and requires every point to
agree with it within 1 mm. A wrong range in one slot, a missing or extra return, or a
ring mix-up fails.

usage: pcap_out_check.py NOISY_PCAP PLY_DIR [SUMMARY_JSON]
"""

import json
import pathlib
import sys

import numpy as np
import plyfile
import velodyne_decoder as vd


def ours(ply_dir):
    ranges, rings = [], []
    for path in sorted(pathlib.Path(ply_dir).rglob("*.ply")):
        v = plyfile.PlyData.read(str(path))["vertex"]
        ranges.append(np.asarray(v["range"], dtype=np.float64))
        rings.append(np.asarray(v["ring"], dtype=np.int64))
    if not ranges:
        sys.exit(f"{ply_dir}: no PLY file")
    return np.concatenate(ranges), np.concatenate(rings)


def theirs(pcap):
    config = vd.Config(model=vd.Model.HDL32E, min_range=0.0, max_range=1000.0)
    ranges, rings, kinds = [], [], []
    for scan in vd.read_pcap(pcap, config):
        pts = scan[1]
        ranges.append(np.linalg.norm(pts[:, 0:3].astype(np.float64), axis=1))
        rings.append(pts[:, 6].astype(np.int64))
        kinds.append(pts[:, 7].astype(np.int64))
    if not ranges:
        sys.exit(f"{pcap}: velodyne_decoder found no scan")
    return np.concatenate(ranges), np.concatenate(rings), np.concatenate(kinds)


def compare(our_r, our_ring, vd_r, vd_ring):
    if len(our_r) != len(vd_r):
        return [f"point count: lidar-noise {len(our_r)}, velodyne_decoder {len(vd_r)}"]
    if not np.array_equal(our_ring, vd_ring):
        bad = int(np.argmax(our_ring != vd_ring))
        return [f"point {bad}: ring {our_ring[bad]} here, {vd_ring[bad]} in velodyne_decoder"]
    fail = []
    diff = our_r - vd_r
    worst = 0.0
    for ring in np.unique(our_ring):
        d = diff[our_ring == ring]
        offset = float(np.median(d))
        if abs(offset) > 0.01:
            fail.append(f"ring {ring}: velodyne_decoder offset {offset:.4f} m (> 1 cm)")
        worst = max(worst, float(np.abs(d - offset).max()))
    if worst > 0.001:
        fail.append(f"ranges differ by up to {worst:.4f} m (> 1 mm) beyond the per-ring offset")
    return fail


def main():
    if len(sys.argv) not in (3, 4):
        sys.exit(__doc__)
    pcap, ply_dir = sys.argv[1], sys.argv[2]
    our_r, our_ring = ours(ply_dir)
    vd_r, vd_ring, vd_kind = theirs(pcap)
    fail = compare(our_r, our_ring, vd_r, vd_ring)
    if len(sys.argv) == 4:
        totals = json.loads(pathlib.Path(sys.argv[3]).read_text())["totals"]["noise"]
        if totals["returns_out"] != len(vd_r):
            fail.append(f"run kept {totals['returns_out']} returns, velodyne_decoder reads {len(vd_r)}")
    if fail:
        print(f"FAIL {pcap}: " + "; ".join(fail))
        sys.exit(1)
    print(
        f"ok {pcap}: {len(vd_r)} points, rings and ranges match velodyne_decoder "
        f"{vd.__version__} (return types {np.unique(vd_kind).tolist()})"
    )


if __name__ == "__main__":
    main()
