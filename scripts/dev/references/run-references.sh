#!/usr/bin/env bash
# Runs the published reference implementations on the same points as the fidelity report
# (frames 2-4 of ../shared/data/hdl32e/monterey.pcap, decoded by our own `convert`) and
# writes docs/fidelity/references.json, which scripts/dev/fidelity/generate.py reads.
#
# Usage: scripts/dev/references/run-references.sh FOG_SIM LISA PYTHON [LISA_SAMPLE]
#   FOG_SIM  snapshot of github:MartinHahner/LiDAR_fog_sim: a bare git dir (as the `fetch`
#            tool or `git clone --bare` gives) or a checked-out tree
#   LISA     snapshot of github:velatkilic/LISA, the same
#   PYTHON   a Python with numpy, scipy (< 1.14: LISA imports scipy.integrate.trapz) and tqdm
#            (Hahner's module imports it), e.g. python3 -m venv /work/refs/venv &&
#            /work/refs/venv/bin/pip install numpy 'scipy<1.14' tqdm
#   LISA_SAMPLE  points LISA's per-point Monte Carlo runs on (default 0 = all; N = a subset
#            of N drawn with seed 1; its per-point Python loop takes about 0.3 ms a point)
# LISA runs twice: as published ("lisa") and with this tool's finite HDL-32E optics swapped
# in by run_lisa.py --optics hdl32e ("lisa_matched": exit aperture, receiver overlap; see
# that script's docstring), on the same points, sample and seed.
# Nothing of the references is copied into the project: they are extracted to a temporary
# directory outside it and imported from there. LISA's Mie library is rebuilt there from
# its mie.c with its own Makefile (falls back to the shipped mie.so if that fails).
set -euo pipefail
export PYTHONDONTWRITEBYTECODE=1  # no __pycache__ in the tree
cd "$(dirname "$0")/../../.."
invocation="scripts/dev/references/run-references.sh $*"
fog_src=$1 lisa_src=$2 py=$3 sample=${4:-0}
capture=../shared/data/hdl32e/monterey.pcap
[ -e "$capture" ] || { echo "needs $capture" >&2; exit 1; }
cargo build --quiet --release --bin lidar-noise
bin=target/release/lidar-noise
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT

# materialise SRC (bare git dir or tree) into DEST, only PATHS; print the commit
materialise() {
  local src=$1 dest=$2
  shift 2
  mkdir -p "$dest"
  if [ -f "$src/HEAD" ] && [ -d "$src/objects" ]; then
    # a snapshot may lack large blobs it does not need (LiDAR_fog_sim's file_lists/*.pkl):
    # git archive then complains about them; the paths asked for are checked below
    { git --git-dir="$src" archive HEAD "$@" 2>/dev/null || true; } | tar -x -C "$dest"
    git --git-dir="$src" rev-parse HEAD
  else
    (cd "$src" && tar -cf - "$@") | tar -x -C "$dest"
    git -C "$src" rev-parse HEAD 2>/dev/null || echo unknown
  fi
  for p in "$@"; do
    [ -e "$dest/$p" ] || { echo "snapshot $src lacks $p" >&2; exit 1; }
  done
}
fog_commit=$(materialise "$fog_src" "$tmp/fog" fog_simulation.py integral_lookup_tables)
lisa_commit=$(materialise "$lisa_src" "$tmp/lisa" pylisa)
if (cd "$tmp/lisa/pylisa" && OS_OPTION=linux make --quiet mie_so >/dev/null 2>&1); then
  mie=rebuilt
else
  mie=shipped
fi

"$bin" --quiet convert "$capture" --frames 2..4 -o "$tmp/points"
plys=("$tmp"/points/*.ply)

fog_cmd="$py scripts/dev/references/run_hahner_fog.py FOG_SIM_TREE POINTS/*.ply"
lisa_cmd="$py scripts/dev/references/run_lisa.py LISA_TREE POINTS/*.ply --rates 1,7.29,25 --snow-rates 1 --sample $sample --seed 1"
matched_cmd="$lisa_cmd --optics hdl32e"
start=$(date +%s)
"$py" scripts/dev/references/run_hahner_fog.py "$tmp/fog" "${plys[@]}" > "$tmp/fog.json"
mid=$(date +%s)
"$py" scripts/dev/references/run_lisa.py "$tmp/lisa" "${plys[@]}" --rates 1,7.29,25 \
  --snow-rates 1 --sample "$sample" --seed 1 > "$tmp/lisa.json"
end=$(date +%s)
"$py" scripts/dev/references/run_lisa.py "$tmp/lisa" "${plys[@]}" --rates 1,7.29,25 \
  --snow-rates 1 --sample "$sample" --seed 1 --optics hdl32e > "$tmp/lisa_matched.json"
matched_end=$(date +%s)
# The real recording's figures (scripts/dev/references/measure_radiate_fog.py, run by hand on
# data kept outside the project) are carried over from the file as it was.
cp docs/fidelity/references.json "$tmp/old.json" 2>/dev/null || echo '{}' > "$tmp/old.json"

"$py" - "$tmp" "$fog_commit" "$lisa_commit" "$mie" "$fog_cmd" "$lisa_cmd" \
  $((mid - start)) $((end - mid)) "$invocation" "$matched_cmd" $((matched_end - end)) \
  <<'PY' > docs/fidelity/references.json
import datetime, json, platform, sys
import numpy, scipy
(tmp, fog_commit, lisa_commit, mie, fog_cmd, lisa_cmd, fog_s, lisa_s, invocation, matched_cmd,
 matched_s) = sys.argv[1:]
points = ("frames 2..4 of ../shared/data/hdl32e/monterey.pcap decoded by "
          "`lidar-noise convert ../shared/data/hdl32e/monterey.pcap --frames 2..4 -o POINTS`")
doc = {
    "generated_by": invocation,
    "note": ("FOG_SIM_TREE / LISA_TREE: the snapshots extracted to a temporary directory; "
             "POINTS: the PLY files of `points` below"),
    "date_utc": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M"),
    "python": platform.python_version(), "numpy": numpy.__version__, "scipy": scipy.__version__,
    "points": points,
    "hahner_fog": {
        "repository": "https://github.com/MartinHahner/LiDAR_fog_sim", "commit": fog_commit,
        "command": fog_cmd, "wall_seconds": int(fog_s),
        **json.load(open(tmp + "/fog.json"))},
    "lisa": {
        "repository": "https://github.com/velatkilic/LISA", "commit": lisa_commit,
        "mie_library": mie + " (pylisa/mie.c via its Makefile)" if mie == "rebuilt"
        else "shipped pylisa/mie.so", "command": lisa_cmd, "wall_seconds": int(lisa_s),
        **json.load(open(tmp + "/lisa.json"))},
    "lisa_matched": {
        "repository": "https://github.com/velatkilic/LISA", "commit": lisa_commit,
        "mie_library": mie + " (pylisa/mie.c via its Makefile)" if mie == "rebuilt"
        else "shipped pylisa/mie.so", "command": matched_cmd, "wall_seconds": int(matched_s),
        **json.load(open(tmp + "/lisa_matched.json"))},
}
old = json.load(open(tmp + "/old.json"))
if "radiate_fog" in old:
    doc["radiate_fog"] = old["radiate_fog"]
json.dump(doc, sys.stdout, indent=1)
print()
PY
echo "wrote docs/fidelity/references.json (Hahner ${fog_commit:0:10}: $((mid - start)) s, LISA ${lisa_commit:0:10}: $((end - mid)) s, matched optics $((matched_end - end)) s)"
