#!/usr/bin/env bash
# Benchmark (not a test): `run DATASET_DIR` on a synthesized KITTI-sized sequence, the
# issue 31 target being a 500-scan sequence on 2 cores through configs/paper.toml in under
# 10 s. One 120,000-point scan is synthesized (64 rings from -24.8 to +2 degrees, 1,875
# azimuths, ranges of a flat ground and a ring of walls, KITTI layout: float32 x y z
# reflectance) and linked 500 times as velodyne/000000.bin ... 000499.bin (a sequence of
# distinct scans reads the same bytes per scan; each is still read, placed, processed and
# written on its own, with its own random streams). Points are placed on the HDL-64E S2
# (--sensor hdl64e: KITTI's sensor; its built-in beams, which the synthetic rings
# approximate).
#
# Everything is in a temporary folder removed at the end (the outputs take about 2.7 GB:
# 500 scans and their fate sidecars). Prints the wall time of the run and of a rerun that
# finds every file done (the resume path).
#
# Usage: scripts/dev/dataset_bench.sh [path/to/lidar-noise] [scans] [threads]
#        (default target/release/lidar-noise, 500 scans, 2 threads)
set -euo pipefail
cd "$(dirname "$0")/../.."
bin=$(realpath "${1:-target/release/lidar-noise}")
scans=${2:-500}
threads=${3:-2}
[ -x "$bin" ] || { echo "dataset_bench: $bin is not built (cargo build --release)"; exit 1; }
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
mkdir -p "$tmp/seq/velodyne"
python3 - "$tmp/scan.bin" <<'EOF'
import math, struct, sys
# 64 rings x 1875 azimuths = 120,000 points: ground at -1.73 m (the KITTI mounting
# height), walls at 25 m for the rings that rise above it.
rows = []
for ring in range(64):
    el = math.radians(-24.8 + ring * (26.8 / 63))
    for a in range(1875):
        az = 2 * math.pi * a / 1875
        if el < -0.01:
            r = min(1.73 / math.sin(-el), 25.0)
        else:
            r = 25.0 + 3 * math.sin(3 * az)
        x = r * math.cos(el) * math.cos(az)
        y = r * math.cos(el) * math.sin(az)
        z = r * math.sin(el)
        rows.append(struct.pack('<4f', x, y, z, ((ring * 7 + a) % 100) / 100))
open(sys.argv[1], 'wb').write(b''.join(rows))
EOF
for i in $(seq 0 $((scans - 1))); do
  ln -s "$tmp/scan.bin" "$tmp/seq/velodyne/$(printf %06d "$i").bin"
done
echo "dataset_bench: $scans scans of $(( $(stat -c %s "$tmp/scan.bin") / 16 )) points, $threads threads, configs/paper.toml, $bin"
t0=$(date +%s.%N)
"$bin" --threads "$threads" run "$tmp/seq" --sensor hdl64e -c configs/paper.toml -o "$tmp/out"
t1=$(date +%s.%N)
"$bin" --threads "$threads" run "$tmp/seq" --sensor hdl64e -c configs/paper.toml -o "$tmp/out"
t2=$(date +%s.%N)
echo "dataset_bench: run $(echo "$t1 - $t0" | bc) s ($(echo "($t1 - $t0) * 1000 / $scans" | bc) ms a scan), rerun with every file done $(echo "$t2 - $t1" | bc) s; outputs $(du -sh "$tmp/out" | cut -f1)"
