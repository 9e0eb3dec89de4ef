#!/usr/bin/env bash
# Regenerates the manual's sensor-factor figures (docs/figures/sensor_*.png): one sweep
# per p-diagram part 1 stage over one of its magnitudes, on the crossroad fixture with
# configs/clear.toml as the base (the stage is added by the --vary shorthand, its other
# options at their defaults), seeds 1..3. Run by hand; review the diff before committing.
set -euo pipefail
cd "$(dirname "$0")/../.."
cargo build --quiet --release --bin lidar-noise
bin=target/release/lidar-noise
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
# stage  option  values  metric shown
while read -r stage key values metric; do
  "$bin" --quiet sweep fixtures/crossroad.pcap --config configs/clear.toml \
    --vary "$stage.$key=$values" --seeds 1..3 -o "$out/$stage"
  cp "$out/$stage/plots/crossroad/$metric.png" "docs/figures/sensor_${stage}_${key}_${metric}.png"
done <<'LIST'
laser_diode sigma_power 0,0.1,0.3,0.6,1 kept
mounting pitch_deg 0,0.5,1,2,4 detected_share
emitter power_factor 1,0.8,0.5,0.2,0.05 kept
mechanics jitter_deg 0,0.05,0.2,0.5,1 detected_share
receiver noise_floor 0,1,3,10,30 kept
motion speed_mps 0,5,10,20,30 detected_share
clock bias_ns 0,1,2,5,10 range_change_rms_m
ambient irradiance 0,0.5,1,2,5 kept
LIST
ls -la docs/figures/sensor_*
