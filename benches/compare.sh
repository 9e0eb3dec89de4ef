#!/usr/bin/env bash
# Compares lidar-noise with the tools a user would pick instead (velodyne_decoder for
# decoding, scikit-learn and optionally Open3D for clustering) on the shared capture.
# Not part of CI: it installs Python packages and takes a few minutes.
#   bash benches/compare.sh            # WITH_OPEN3D=1 to include Open3D (large download)
set -euo pipefail
cd "$(dirname "$0")/.."
capture=../shared/data/hdl32e/monterey.pcap
[ -e "$capture" ] || { echo "SKIPPED: $capture is absent"; exit 0; }
venv="${TMPDIR:-/tmp}/lidar-noise-bench-venv"
[ -x "$venv/bin/python" ] || python3 -m venv "$venv"
pkgs="velodyne-decoder numpy scikit-learn plyfile"
[ "${WITH_OPEN3D:-0}" = 1 ] && pkgs="$pkgs open3d"
"$venv/bin/pip" install --quiet --disable-pip-version-check $pkgs
cargo build --quiet --release --bin lidar-noise --example decode_speed
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
echo "== lidar-noise"
target/release/examples/decode_speed "$capture" 40
target/release/lidar-noise --quiet run -c configs/clear.toml --frames 1 -o "$out" "$capture"
cargo bench --quiet --bench pipeline -- ground_plus_clustering 2>&1 | grep -E "frame|time:" || true
cargo bench --quiet --bench cluster -- monterey 2>&1 | grep -E "time:" || true
echo "== alternatives"
"$venv/bin/python" scripts/dev/bench_compare.py "$capture" "$out/monterey/frame_00001.ply"
