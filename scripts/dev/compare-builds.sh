#!/usr/bin/env bash
# Runs two builds of lidar-noise on the same inputs and diffs their output folders byte
# for byte: every config in configs/ on the fixtures, frames of the shared HDL-32E capture,
# the shared VLP-16 capture, a synthesized capture of every described sensor (made by the
# OLD build, and compared too) and a point-cloud scan; plus `info`, `convert` and
# `--pcap-out`. For refactors that must not change a byte (issue 51).
#
#   scripts/dev/compare-builds.sh OLD_BINARY NEW_BINARY [WORK_DIR]
#
# Exit 0 when every output is identical, 1 with the differing files listed. The shared
# captures are skipped (and said so) when ../shared is absent. Lines of run.json and the
# like that name the build (version, commit) are compared as they are: both builds must be
# made from trees of the same version.
set -euo pipefail
old=$(realpath "$1")
new=$(realpath "$2")
work=${3:-$(mktemp -d)}
root=$(cd "$(dirname "$0")/../.." && pwd)
shared=${LIDAR_NOISE_SHARED:-$root/../shared/data}
mkdir -p "$work"
inputs="$work/inputs"
mkdir -p "$inputs"

echo "work folder: $work" >&2
# Synthesized captures of every sensor, made once by the old build (the new build's
# captures are compared below).
sensors=(hdl32e vlp16 puck-hi-res vlp32c "hdl64e s2" "hdl64e s3" vls128 "vls128 fw5.1")
for s in "${sensors[@]}"; do
  name=${s// /-}
  scene=(--preset crossroad)
  case $s in hdl64e*) scene=(--random 3) ;; esac
  for b in old new; do
    bin=$old; [ $b = new ] && bin=$new
    "$bin" --quiet synth --sensor "$s" --rotations 3 "${scene[@]}" --seed 2 -o "$work/$b/synth-$name"
  done
  cp "$(ls "$work/old/synth-$name"/*.pcap | head -n 1)" "$inputs/$name.pcap"
done

captures=("$root"/fixtures/*.pcap "$inputs"/*.pcap)
frames_of=()
if [ -f "$shared/hdl32e/monterey.pcap" ]; then
  captures+=("$shared/hdl32e/monterey.pcap")
else
  echo "SKIPPED: $shared/hdl32e/monterey.pcap absent" >&2
fi
if [ -f "$shared/negative/vlp16_mrpt.pcap" ]; then
  captures+=("$shared/negative/vlp16_mrpt.pcap")
else
  echo "SKIPPED: $shared/negative/vlp16_mrpt.pcap absent" >&2
fi

# A KITTI-layout scan and a nuScenes-layout scan, converted from the crossroad fixture by
# the old build (x y z intensity as float32 rows).
python3 - "$root/fixtures/crossroad.pcap" "$inputs" "$old" <<'EOF'
import struct, subprocess, sys, pathlib, tempfile
pcap, out, old = sys.argv[1:4]
tmp = tempfile.mkdtemp()
subprocess.run([old, "--quiet", "convert", pcap, "-o", tmp, "--frames", "0"], check=True)
ply = sorted(pathlib.Path(tmp).rglob("*.ply"))[0]
data = ply.read_bytes()
head_end = data.index(b"end_header\n") + len(b"end_header\n")
header = data[:head_end].decode().splitlines()
props, count = [], 0
for line in header:
    p = line.split()
    if p[:2] == ["element", "vertex"]:
        count = int(p[2])
    elif p[:1] == ["property"]:
        props.append((p[1], p[2]))
sizes = {"float": 4, "float32": 4, "double": 8, "float64": 8, "uchar": 1, "uint8": 1,
         "char": 1, "int8": 1, "ushort": 2, "uint16": 2, "short": 2, "int16": 2,
         "uint": 4, "uint32": 4, "int": 4, "int32": 4}
codes = {"float": "f", "float32": "f", "double": "d", "float64": "d", "uchar": "B",
         "uint8": "B", "char": "b", "int8": "b", "ushort": "H", "uint16": "H",
         "short": "h", "int16": "h", "uint": "I", "uint32": "I", "int": "i", "int32": "i"}
fmt = "<" + "".join(codes[t] for t, _ in props)
step = struct.calcsize(fmt)
names = [n for _, n in props]
kitti, nus = bytearray(), bytearray()
for i in range(count):
    row = dict(zip(names, struct.unpack_from(fmt, data, head_end + i * step)))
    kitti += struct.pack("<4f", row["x"], row["y"], row["z"], row["intensity"] / 255.0)
    nus += struct.pack("<5f", row["x"], row["y"], row["z"], float(row["intensity"]), float(row.get("ring", 0)))
pathlib.Path(out, "scan.bin").write_bytes(bytes(kitti))
pathlib.Path(out, "scan.pcd.bin").write_bytes(bytes(nus))
EOF
scans=("$inputs/scan.bin" "$inputs/scan.pcd.bin")

run_both() { # label, args...
  local label=$1; shift
  for b in old new; do
    local bin=$old; [ $b = new ] && bin=$new
    "$bin" --quiet "$@" -o "$work/$b/$label" >"$work/$b/$label.stdout" 2>"$work/$b/$label.stderr" \
      || echo "exit $?" >>"$work/$b/$label.stderr"
  done
}

for c in "${captures[@]}"; do
  base=$(basename "$c" .pcap)
  for b in old new; do
    bin=$old; [ $b = new ] && bin=$new
    mkdir -p "$work/$b"
    "$bin" info "$c" >"$work/$b/info-$base.txt" 2>&1 || echo "exit $?" >>"$work/$b/info-$base.txt"
  done
  frames=()
  case $base in monterey) frames=(--frames 2..4) ;; esac
  run_both "convert-$base" convert "$c" "${frames[@]}"
  for cfg in "$root"/configs/*.toml; do
    run_both "run-$base-$(basename "$cfg" .toml)" run "$c" -c "$cfg" --seed 3 "${frames[@]}" --keep-dropped
  done
  for cfg in clear paper rain; do
    run_both "pcap-out-$base-$cfg" run "$c" -c "$root/configs/$cfg.toml" --seed 5 "${frames[@]}" --no-ply --pcap-out
  done
done
for s in "${scans[@]}"; do
  base=$(basename "$s")
  for cfg in "$root"/configs/*.toml; do
    run_both "run-$base-$(basename "$cfg" .toml)" run "$s" -c "$cfg" --seed 3 --keep-dropped
  done
done

run_both sweep-crossroad sweep "$root/fixtures/crossroad.pcap" -c "$root/configs/rain.toml" \
  --vary rain.rate_mm_h=0,10 --seeds 2

if diff -r -q "$work/old" "$work/new"; then
  echo "identical: $(find "$work/old" -type f | wc -l) files" >&2
else
  echo "DIFFERENT (above)" >&2
  exit 1
fi
