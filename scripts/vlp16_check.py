#!/usr/bin/env python3
"""Cross-check of the VLP-16 decoder (src/sensor/decode.rs) with velodyne_decoder (pip).

velodyne_decoder decodes ../shared/data/negative/vlp16_mrpt.pcap as a VLP-16 (bundled
VLP-16.yml calibration, no minimum range); the points of its frame 1 are written to a
CSV (x, y, z, intensity, time, ring; time in seconds past the hour: the frame's device
stamp modulo 3600 plus the point's relative time), then the ignored test
`real_vlp16_capture_matches_velodyne_decoder` of tests/sensor_models.rs matches every
point to the return of the same ring fired at the same microsecond and checks the
position difference and the counts per ring.

usage: vlp16_check.py [PCAP] [CSV]      (run from the project root)
"""

import os
import pathlib
import subprocess
import sys

import velodyne_decoder as vd

root = pathlib.Path(__file__).resolve().parent.parent
pcap = sys.argv[1] if len(sys.argv) > 1 else str(root / "../shared/data/negative/vlp16_mrpt.pcap")
out = sys.argv[2] if len(sys.argv) > 2 else "/tmp/vlp16_mrpt.frame1.csv"
if not os.path.exists(pcap):
    print(f"SKIPPED: {pcap} is absent")
    sys.exit(0)

config = vd.Config(model=vd.Model.VLP16, min_range=0.0)
frames = list(vd.read_pcap(pcap, config, as_pcl_structs=True))
stamp, points = frames[1]
base = stamp.device % 3600.0
with open(out, "w") as f:
    f.write("x,y,z,intensity,time,ring\n")
    for p in points:
        f.write("%.9g,%.9g,%.9g,%d,%.9f,%d\n" % (p["x"], p["y"], p["z"], p["intensity"], base + float(p["time"]), p["ring"]))
print(f"velodyne_decoder {vd.__version__}: {len(frames)} frames, frame 1 has {len(points)} points -> {out}")
env = dict(os.environ, VLP16_REFERENCE_CSV=out)
cmd = ["cargo", "test", "--test", "sensor_models", "--", "--ignored", "--nocapture",
       "real_vlp16_capture_matches_velodyne_decoder"]
sys.exit(subprocess.run(cmd, cwd=root, env=env).returncode)
