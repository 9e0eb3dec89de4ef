#!/usr/bin/env bash
# Regenerates the manual's weather figures and table (p-diagram 11):
# - docs/figures/weather_fog_visibility_m_detected_share.png: fog at MOR 50-1000 m;
# - docs/figures/weather_rain_rate_mm_h_detected_share.png: rain (the default model, mie) at 0.5-30 mm/h;
# - docs/figures/fog_sensitivity.md: how the fog results move with the overlap model
#   (the HDL-32E's biaxial geometry, or Hahner's 0.9-1.0 m ramp) and the droplets
#   (Hahner's beta_r, Mie advection or radiation fog): share of labelled objects detected (sweep, mean over seeds) /
#   fog points (returns replaced or added by fog echoes, from `run`'s summary.json) per
#   recorded return.
# All on the crossroad fixture with configs/clear.toml as the base (the stage added by
# the --vary / --set shorthand, its other options at their defaults), seeds 1..3 for
# the sweeps. Run by hand; review the diff before committing.
set -euo pipefail
cd "$(dirname "$0")/../.."
cargo build --quiet --release --bin lidar-noise
bin=target/release/lidar-noise
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
capture=fixtures/crossroad.pcap
"$bin" --quiet sweep "$capture" --config configs/clear.toml \
  --vary fog.visibility_m=50,100,150,200,300,400,600,800,1000 --seeds 1..3 -o "$out/fog"
cp "$out/fog/plots/crossroad/detected_share.png" docs/figures/weather_fog_visibility_m_detected_share.png
"$bin" --quiet sweep "$capture" --config configs/clear.toml \
  --vary rain.rate_mm_h=0.5,1,2,4,7,10,15,20,30 --seeds 1..3 -o "$out/rain"
cp "$out/rain/plots/crossroad/detected_share.png" docs/figures/weather_rain_rate_mm_h_detected_share.png

# Sensitivity table: per (overlap, droplets) setting one sweep over V for the share of
# objects detected, and one run per cell for the returns replaced or added by fog echoes.
visibilities="50 150 300 600 1000 10000"
settings="biaxial:hahner biaxial:advection biaxial:radiation linear:hahner"
table=docs/figures/fog_sensitivity.md
{
  echo "| overlap | droplets | $(for v in $visibilities; do printf 'V = %s m | ' "$v"; done)"
  echo "|---|---|$(for _ in $visibilities; do printf -- '---|'; done)"
  for s in $settings; do
    r2=${s%%:*}
    gain=${s##*:}
    cfg="$out/fog-$r2-$gain.toml"
    { cat configs/clear.toml; printf '\n[[noise]]\ntype = "fog"\nvisibility_m = 1000.0\noverlap = "%s"\ndroplets = "%s"\n' "$r2" "$gain"; } > "$cfg"
    "$bin" --quiet sweep "$capture" --config "$cfg" \
      --vary "fog.visibility_m=${visibilities// /,}" --seeds 1..3 -o "$out/sens-$r2-$gain"
    row="| $r2 | $gain |"
    for v in $visibilities; do
      dir="$out/run-$r2-$gain-$v"
      "$bin" --quiet run "$capture" -c "$cfg" --set "fog.visibility_m=$v" --no-ply -o "$dir"
      row="$row $(python3 - "$dir/crossroad/summary.json" "$out/sens-$r2-$gain/aggregate.csv" "$v" <<'PY'
import csv, json, sys
noise = json.load(open(sys.argv[1]))["totals"]["noise"]
spurious = noise.get("spurious", {})  # absent when no echo won
fog = spurious.get("replaced", 0) + spurious.get("added", 0)
det = next(float(r["detected_share_mean"]) for r in csv.DictReader(open(sys.argv[2]))
           if float(r["fog.visibility_m"]) == float(sys.argv[3]))
print(f"{det:.2f} / {100 * fog / noise['returns_in']:.0f} %")
PY
) |"
    done
    echo "$row"
  done
} > "$table"
cat "$table"
