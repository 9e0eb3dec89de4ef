#!/usr/bin/env bash
# Reproduces the reference study (occlusion of five lasers, Goodin rain at 7 mm/h, both) with
# the object metrics by distance band, for every ground method, on the crossroad and parking
# fixtures, five randomized street scenes (seeds 7001-7005: neither the ground method's
# tuning seeds 1-6 nor its test seeds) and the shared real capture. Seeds 1..3 of the noise.
# Writes docs/figures/study_by_band.md (included in the manual's "The reference study, reproduced"). Run by hand; review the diff.
set -euo pipefail
cd "$(dirname "$0")/../.."
cargo build --quiet --release --bin lidar-noise
bin=target/release/lidar-noise
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
sweep() {
  local dir=$1
  shift
  "$bin" --quiet sweep "$@" --config configs/paper.toml \
    --vary ground.method=range-image,ransac,patchwork --vary occlusion=on,off \
    --vary rain.rate_mm_h=0,7 --seeds 1..3 -o "$dir"
}
args=()
sweep "$out/crossroad" fixtures/crossroad.pcap
args+=("crossroad=$out/crossroad")
sweep "$out/parking" fixtures/parking.pcap
args+=("parking=$out/parking")
. scripts/dev/lib/scenes.sh
for seed in "${random_seeds[@]}"; do
  make_random_scene "$seed"
  sweep "$out/random-$seed" "$out/scenes/random-$seed"/*.pcap
  args+=("random (5 scenes)=$out/random-$seed")
done
if [ -e ../shared/data/hdl32e/monterey.pcap ]; then
  sweep "$out/monterey" ../shared/data/hdl32e/monterey.pcap
  args+=("monterey (real)=$out/monterey")
else
  echo "SKIPPED: ../shared/data is absent; the table has no real-capture rows" >&2
fi
python3 scripts/dev/study_table.py "${args[@]}" > docs/figures/study_by_band.md
cat docs/figures/study_by_band.md
