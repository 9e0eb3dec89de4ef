#!/usr/bin/env bash
# Whole-process speed on the shared capture (17 frames, 1.49 s of recording at 11.8 Hz),
# the paper pipeline with PLY and reports written, against the Python pipeline a user
# would assemble (scripts/python_peer.py: velodyne_decoder + numpy noise + Patchwork++ +
# Open3D DBSCAN + plyfile), measured in the same run. Also `convert` against
# velodyne_decoder + plyfile writing the same per-frame PLY. Not part of CI: it installs
# Python packages (Open3D is large).
#   bash benches/realtime.sh [RUNS]     # RUNS timed runs per setting (default 15)
set -euo pipefail
cd "$(dirname "$0")/.."
capture=../shared/data/hdl32e/monterey.pcap
[ -e "$capture" ] || { echo "SKIPPED: $capture is absent"; exit 0; }
runs=${1:-15}
recording_s=1.49
venv="${TMPDIR:-/tmp}/lidar-noise-peer-venv"
[ -x "$venv/bin/python" ] || python3 -m venv "$venv"
"$venv/bin/pip" install --quiet --disable-pip-version-check velodyne-decoder numpy plyfile \
  pypatchworkpp open3d
# Open3D's wheel links libusb-1.0, which a fresh Debian machine lacks: without it the peer
# dies at import, and the comparison would print no peer line at all.
if ! "$venv/bin/python" -c "import open3d" 2>/dev/null; then
  if [ "$(id -u)" = 0 ]; then sudo=(); elif command -v sudo >/dev/null && sudo -n true 2>/dev/null; then sudo=(sudo -n); else
    echo "realtime.sh: Open3D cannot be imported (libusb-1.0 missing?) and apt-get needs root or passwordless sudo: install libusb-1.0-0" >&2
    exit 1
  fi
  { "${sudo[@]}" apt-get install -y -qq libusb-1.0-0 || { "${sudo[@]}" apt-get update -qq && DEBIAN_FRONTEND=noninteractive "${sudo[@]}" apt-get install -y -qq libusb-1.0-0; }; } >/dev/null
  "$venv/bin/python" -c "import open3d" || { echo "realtime.sh: Open3D still cannot be imported (error above)" >&2; exit 1; }
fi
cargo build --quiet --release --bin lidar-noise
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
# Median and best wall time of RUNS runs of a command (fresh output folder each time).
timeit() {
  local label=$1
  shift
  python3 - "$runs" "$label" "$out" "$@" <<'PY'
import shutil, statistics, subprocess, sys, time
runs, label, out, cmd = int(sys.argv[1]), sys.argv[2], sys.argv[3], sys.argv[4:]
times = []
for _ in range(runs):
    shutil.rmtree(f"{out}/o", ignore_errors=True)
    t0 = time.perf_counter()
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    times.append(time.perf_counter() - t0)
med, best = statistics.median(times), min(times)
print(f"{label}: median {med*1e3:.1f} ms, best {best*1e3:.1f} ms, "
      f"{17/med:.1f} frames/s, {1.49/med:.1f}x real time (median of {runs})")
PY
}
bin=target/release/lidar-noise
# One core: the decoding thread and the one worker pinned to CPU 0 (without the pin the
# decoder would overlap on the second core). Two: both cores, two workers.
RAYON_NUM_THREADS=1 timeit "lidar-noise run, paper config, 1 core" \
  taskset -c 0 "$bin" --quiet run -c configs/paper.toml -o "$out/o" "$capture"
RAYON_NUM_THREADS=2 timeit "lidar-noise run, paper config, 2 cores" \
  "$bin" --quiet run -c configs/paper.toml -o "$out/o" "$capture"
RAYON_NUM_THREADS=2 timeit "lidar-noise convert, 2 cores" \
  "$bin" --quiet convert -o "$out/o" "$capture"
echo "== Python peer (same machine, same run)"
for _ in 1 2 3; do
  # Its errors are shown: a failing peer must not pass for a missing line.
  "$venv/bin/python" scripts/python_peer.py "$capture" "$out/peer" | grep peer
done
"$venv/bin/python" - "$capture" "$out/conv" <<'PY'
import os, sys, time
import numpy as np, plyfile, velodyne_decoder as vd
capture, out = sys.argv[1], sys.argv[2]
os.makedirs(out, exist_ok=True)
best = float("inf")
for _ in range(3):
    t0 = time.perf_counter()
    n = 0
    for _s, pts in vd.read_pcap(capture, vd.Config(model=vd.Model.HDL32E)):
        v = np.empty(len(pts), dtype=[("x", "f4"), ("y", "f4"), ("z", "f4"),
                                      ("intensity", "u1"), ("ring", "u1"), ("time", "f8")])
        v["x"], v["y"], v["z"] = pts[:, 0], pts[:, 1], pts[:, 2]
        v["intensity"], v["ring"], v["time"] = pts[:, 3], pts[:, 6], pts[:, 4]
        plyfile.PlyData([plyfile.PlyElement.describe(v, "vertex")]).write(f"{out}/f{n:05d}.ply")
        n += 1
    best = min(best, time.perf_counter() - t0)
print(f"velodyne_decoder + plyfile convert: best {best*1e3:.1f} ms for {n} frames")
PY
