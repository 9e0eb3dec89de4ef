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
       pcap_out_check.py --make-dual OUT.pcap   (a two-rotation dual-return capture,
                                                 none of the fixtures being dual)
"""

import json
import pathlib
import struct
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
        # Dual mode: velodyne_decoder lists both returns of a laser together (last, then
        # strongest); lidar-noise lists the packet's blocks in order (the firing's last
        # block, then its strongest). Reorder by firing (column), then return type, and
        # keep the order within (a no-op for single-return captures).
        order = np.lexsort((np.arange(len(pts)), -pts[:, 7], pts[:, 5]))
        pts = pts[order]
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


def make_dual(path):
    """Two rotations in dual mode (0x39): even block last return at 10 m + 2 mm * laser,
    odd block strongest at 20 m + 2 mm * laser, 0.2 degrees per firing."""
    out = bytearray(struct.pack("<IHHiIII", 0xA1B2C3D4, 2, 4, 0, 0, 65535, 1))
    ts, firing, ident = 1000, 0, 0
    while firing * 20 < 2 * 36000 + 600:
        payload = bytearray()
        for b in range(12):
            payload += b"\xff\xee" + struct.pack("<H", ((firing + b // 2) * 20) % 36000)
            for j in range(32):
                payload += struct.pack("<HB", (10000 if b % 2 else 5000) + j, (b * 3 + j) % 256)
        payload += struct.pack("<I", ts) + bytes([0x39, 0x21])
        ip = bytearray(struct.pack(">BBHHHBBH4s4s", 0x45, 0, 28 + len(payload), ident, 0x4000,
                                   64, 17, 0, bytes([192, 168, 1, 201]), bytes([255] * 4)))
        total = sum(struct.unpack(">10H", bytes(ip)))
        total = (total & 0xFFFF) + (total >> 16)
        total = (total & 0xFFFF) + (total >> 16)
        ip[10:12] = struct.pack(">H", ~total & 0xFFFF)
        frame = (b"\xff" * 6 + bytes([0x60, 0x76, 0x88, 0, 0, 1]) + b"\x08\x00" + bytes(ip)
                 + struct.pack(">HHHH", 2368, 2368, 8 + len(payload), 0) + bytes(payload))
        out += struct.pack("<IIII", 1_700_000_000, ts, len(frame), len(frame)) + frame
        firing, ts, ident = firing + 6, ts + 277, ident + 1
    pathlib.Path(path).write_bytes(bytes(out))


def main():
    if len(sys.argv) == 3 and sys.argv[1] == "--make-dual":
        make_dual(sys.argv[2])
        return
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
