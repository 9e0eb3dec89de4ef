#!/usr/bin/env bash
# The reference study's real question with `sweep --interactions`: occlusion of five lasers
# and Goodin rain at 7 mm/h, each alone and together, object detection by distance band,
# for every ground method, on the crossroad and parking fixtures, five randomized street
# scenes pooled (seeds 7001-7005, as in make-study-tables.sh) and the shared real capture;
# then the p-diagram sensor stages (configs/pdiagram-sensor.toml) on the same scenes with
# the default ground method. Noise seeds 1..3.
# Writes docs/figures/interactions_by_band.md (included in the manual's "Interactions between noise stages"). Run by hand; review
# the diff.
set -euo pipefail
cd "$(dirname "$0")/../.."
cargo build --quiet --release --bin lidar-noise
bin=target/release/lidar-noise
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
. scripts/dev/lib/scenes.sh
make_scenes
run() {
  local dir=$1 config=$2
  shift 2
  "$bin" --quiet sweep "$@" --config "$config" --interactions --seeds 1..3 -o "$dir"
}
args=()
for method in range-image ransac patchwork; do
  run "$out/paper-$method" configs/paper.toml fixtures/crossroad.pcap fixtures/parking.pcap \
    "${real[@]}" --set ground.method=$method
  run "$out/paper-random-$method" configs/paper.toml "${random[@]}" --set ground.method=$method
  args+=("paper:$method=$out/paper-$method" "paper:$method=$out/paper-random-$method")
done
run "$out/sensor" configs/pdiagram-sensor.toml fixtures/crossroad.pcap fixtures/parking.pcap \
  "${real[@]}"
run "$out/sensor-random" configs/pdiagram-sensor.toml "${random[@]}"
args+=("sensor:patchwork=$out/sensor" "sensor:patchwork=$out/sensor-random")
python3 scripts/dev/interaction_table.py "${args[@]}" > docs/figures/interactions_by_band.md
cat docs/figures/interactions_by_band.md
