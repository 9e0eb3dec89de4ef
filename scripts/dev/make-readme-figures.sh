#!/usr/bin/env bash
# Regenerates the manual's reference-study figures and tables (docs/figures/) from the
# crossroad fixture and the shared capture. Run by hand; review the diff before committing.
set -euo pipefail
cd "$(dirname "$0")/../.."
cargo build --quiet --release --bin lidar-noise
bin=target/release/lidar-noise
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
sweep() {
  "$bin" --quiet sweep "$1" --config configs/paper.toml \
    --vary rain.rate_mm_h=0,0.5,1,2,3,5,7 --vary occlusion=on,off --seeds 1..3 -o "$2"
}
sweep fixtures/crossroad.pcap "$out/crossroad"
cp "$out/crossroad/plots/birdseye_crossroad_frame0.png" docs/figures/
cp "$out/crossroad/aggregate.csv" docs/figures/crossroad_aggregate.csv
if [ -e ../shared/data/hdl32e/monterey.pcap ]; then
  sweep ../shared/data/hdl32e/monterey.pcap "$out/monterey"
  cp "$out/monterey/plots/birdseye_monterey_frame1.png" docs/figures/

  cp "$out/monterey/aggregate.csv" docs/figures/monterey_aggregate.csv
fi
ls -la docs/figures
