#!/usr/bin/env python3
"""Cross-check of the VLP-16 decoder (src/sensor/decode.rs) with velodyne_decoder (pip).

velodyne_decoder decodes ../shared/data/negative/vlp16_mrpt.pcap as a VLP-16 (bundled
VLP-16.yml calibration, no minimum range); the points of its frame 1 are written to a
CSV (x, y, z, intensity, time, ring; time in seconds past the hour: the frame's device
stamp modulo 3600 plus the point's relative time), then the ignored test
`real_vlp16_capture_matches_velodyne_decoder` of tests/integration/sensor_models.rs matches every
point to the return of the same ring fired at the same microsecond and checks the
position difference and the counts per ring.

usage: vlp16_check.py [PCAP] [CSV]      (run from the project root)
"""

import os
import pathlib
import subprocess
import sys

import velodyne_decoder as vd

root = pathlib.Path(__file__).resolve().parents[2]
pcap = sys.argv[1] if len(sys.argv) > 1 else str(root / "../shared/data/negative/vlp16_mrpt.pcap")
out = sys.argv[2] if len(sys.argv) > 2 else "/tmp/vlp16_mrpt.frame1.csv"
if not os.path.exists(pcap):
    print(f"SKIPPED: {pcap} is absent")
    sys.exit(0)

config = vd.Config(model=vd.Model.VLP16, min_range=0.0)
try:
    frames = list(vd.read_pcap(pcap, config, as_pcl_structs=True))
except RuntimeError as e:
    # A VLP-16 whose product byte says HDL-32E (0x21; VeloView's test capture):
    # velodyne_decoder refuses it, so it reads a copy with byte 1205 of every 1206-byte
    # payload set to 0x22 (classic pcap, Ethernet/IPv4/UDP: payload at 42); lidar-noise
    # reads the original and must tell the VLP-16 by structure.
    import struct

    print(f"velodyne_decoder: {e}: reading a copy with the product byte set to 0x22")
    data = bytearray(open(pcap, "rb").read())
    at = 24
    while at + 16 <= len(data):
        incl = struct.unpack_from("<I", data, at + 8)[0]
        if incl == 42 + 1206 and data[at + 16 + 42 + 1205] == 0x21:
            data[at + 16 + 42 + 1205] = 0x22
        at += 16 + incl
    fixed = out + ".product22.pcap"
    open(fixed, "wb").write(data)
    frames = list(vd.read_pcap(fixed, config, as_pcl_structs=True))
stamp, points = frames[1]
base = stamp.device % 3600.0
with open(out, "w") as f:
    f.write("x,y,z,intensity,time,ring\n")
    for p in points:
        f.write("%.9g,%.9g,%.9g,%d,%.9f,%d\n" % (p["x"], p["y"], p["z"], p["intensity"], base + float(p["time"]), p["ring"]))
print(f"velodyne_decoder {vd.__version__}: {len(frames)} frames, frame 1 has {len(points)} points -> {out}")
env = dict(os.environ, VLP16_REFERENCE_CSV=out, VLP16_PCAP=str(pathlib.Path(pcap).resolve()))
cmd = ["cargo", "test", "--test", "integration", "--", "--ignored", "--nocapture",
       "sensor_models::real_vlp16_capture_matches_velodyne_decoder"]
sys.exit(subprocess.run(cmd, cwd=root, env=env).returncode)
