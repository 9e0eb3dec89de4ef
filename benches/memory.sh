#!/usr/bin/env bash
# Peak RSS of `run --no-ply`, `run` and `run --no-ply --pcap-out` on 1x, 10x and 100x the
# shared capture (copies back to back with the clocks continuing). Target: the 100x peak
# within 1.3x of the 10x.
# Usage: benches/memory.sh [CAPTURE]   (default ../shared/data/hdl32e/monterey.pcap)
#        MODES='pcap-out' benches/memory.sh   (only some of the modes)
set -euo pipefail
cd "$(dirname "$0")/.."
capture=${1:-../shared/data/hdl32e/monterey.pcap}
if [ ! -e "$capture" ]; then
  echo "SKIPPED: $capture is absent"
  exit 0
fi
profile=${PROFILE:-debug}  # PROFILE=release for optimised numbers (builds every dependency again)
flag=$([ "$profile" = release ] && echo --release || true)
cargo build --quiet $flag --bin lidar-noise --example repeat_capture
bin=target/$profile/lidar-noise
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

# Peak resident set of a command, in MB, from the kernel's accounting of waited children.
peak_mb() {
  python3 - "$@" <<'PY'
import resource, subprocess, sys
subprocess.run(sys.argv[1:], check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
print(f"{resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024:.1f}")
PY
}

printf '%-6s %-10s %12s\n' copies mode "peak RSS MB"
for n in 1 10 100; do
  "target/$profile/examples/repeat_capture" "$capture" "$n" "$work/x$n.pcap"
  for mode in ${MODES:-no-ply ply pcap-out}; do
    args=(run "$work/x$n.pcap" -o "$work/out-$n-$mode" --quiet)
    [ "$mode" = no-ply ] && args+=(--no-ply)
    [ "$mode" = pcap-out ] && args+=(--no-ply --pcap-out)
    printf '%-6s %-10s %12s\n' "${n}x" "$mode" "$(peak_mb "$bin" "${args[@]}")"
    rm -rf "$work/out-$n-$mode"
  done
done
