#!/usr/bin/env bash
# The reference study again with physical rain (issue 29): the tables of
# scripts/dev/make-study-tables.sh (detected share by distance band) and
# scripts/dev/make-interaction-tables.sh (occlusion x rain interaction, configs/paper.toml part)
# for every ground method, once with configs/paper.toml as it is (Goodin rain, 7 mm/h) and
# once with its rain switched to `model = "mie"` (scripts/dev/fidelity/mie_config.py: the same
# rate, Goodin's range_noise line removed), side by side in docs/study-mie.md.
# Same scenes and seeds as those scripts: crossroad and parking fixtures, five randomized
# street scenes (synth seeds 7001-7005), the shared real capture when present; noise seeds
# 1..3. A build whose rain has no `model` option gets the Goodin half and a note.
# Run by hand (about 15-25 minutes on 2 busy cores; the time is written into the page);
# review the diff.
set -euo pipefail
export PYTHONDONTWRITEBYTECODE=1  # no __pycache__ in the tree
cd "$(dirname "$0")/../.."
# LIDAR_NOISE_BIN: use that binary instead of building this tree's; STUDY_MIE_OUT: write
# the page there instead of docs/study-mie.md (both for trying another build).
bin=${LIDAR_NOISE_BIN:-target/release/lidar-noise}
page=${STUDY_MIE_OUT:-docs/study-mie.md}
[ -n "${LIDAR_NOISE_BIN:-}" ] || cargo build --quiet --release --bin lidar-noise
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
python3 scripts/dev/fidelity/mie_config.py configs/paper.toml mie > "$out/paper-mie.toml"
# the Goodin half says `model = "goodin"` explicitly (a build whose default is mie must not
# run the study's rain as mie); a build without the option runs paper.toml as it is
python3 scripts/dev/fidelity/mie_config.py configs/paper.toml goodin > "$out/paper-goodin.toml"
goodin_cfg=configs/paper.toml
if "$bin" --quiet validate "$out/paper-goodin.toml" > /dev/null 2>&1; then
  goodin_cfg="$out/paper-goodin.toml"
fi
models=(goodin)
mie_error=""
if "$bin" --quiet validate "$out/paper-mie.toml" > /dev/null 2> "$out/mie.err"; then
  models+=(mie)
else
  mie_error=$(tail -n 1 "$out/mie.err" | sed 's|^.*paper-mie.toml: ||')
  echo "mie rain not available in this build: $mie_error" >&2
fi
. scripts/dev/lib/scenes.sh
make_scenes
timing=()
for model in "${models[@]}"; do
  cfg=$goodin_cfg
  [ "$model" = mie ] && cfg="$out/paper-mie.toml"
  start=$(date +%s)
  d="$out/$model"
  # a failing sweep of the mie half (e.g. a value its model rejects) leaves the Goodin
  # half and a note instead of no page (set +e around the subshell: inside an `if` or
  # `||`, bash would ignore its set -e)
  set +e
  (
  set -e
  band() {
    local dir=$1
    shift
    "$bin" --quiet sweep "$@" --config "$cfg" \
      --vary ground.method=range-image,ransac,patchwork --vary occlusion=on,off \
      --vary rain.rate_mm_h=0,7 --seeds 1..3 -o "$dir"
  }
  band "$d/band/crossroad" fixtures/crossroad.pcap
  band "$d/band/parking" fixtures/parking.pcap
  for seed in 7001 7002 7003 7004 7005; do
    band "$d/band/random-$seed" "$out/scenes/random-$seed"/*.pcap
  done
  [ ${#real[@]} -gt 0 ] && band "$d/band/monterey" "${real[@]}"
  for method in range-image ransac patchwork; do
    "$bin" --quiet sweep fixtures/crossroad.pcap fixtures/parking.pcap "${real[@]}" \
      --config "$cfg" --interactions --seeds 1..3 -o "$d/inter/$method" \
      --set ground.method=$method
    "$bin" --quiet sweep "${random[@]}" --config "$cfg" --interactions --seeds 1..3 \
      -o "$d/inter/random-$method" --set ground.method=$method
  done
  ) 2> "$out/$model.err"
  rc=$?
  set -e
  if [ $rc -ne 0 ]; then
    cat "$out/$model.err" >&2
    [ "$model" = goodin ] && exit 1
    mie_error="its sweeps failed: $(tail -n 1 "$out/$model.err")"
    rm -rf "$d"
    continue
  fi
  timing+=("$model=$(($(date +%s) - start))")
done
python3 scripts/dev/fidelity/study_mie.py "$out" "$mie_error" "${timing[@]}" > "$page"
echo "wrote $page (${timing[*]} s)"
