#!/usr/bin/env bash
# Regenerates docs/fidelity.md (issue 29): every weather, optics, attack and sensor stage
# against its anchor, measured from the tool's own output on frames 2-4 of the shared
# real capture (configs/clear.toml plus one stage), with the reference implementations'
# numbers from docs/fidelity/references.json (regenerate those with
# scripts/dev/references/run-references.sh; they need snapshots of the references and a
# Python with numpy/scipy, the report itself needs only python3).
# About 1-2 minutes on 2 cores after the build. Run by hand; review the diff.
set -euo pipefail
export PYTHONDONTWRITEBYTECODE=1  # no __pycache__ in the tree
cd "$(dirname "$0")/../.."
if [ ! -e ../shared/data/hdl32e/monterey.pcap ]; then
  echo "SKIPPED: ../shared/data is absent; the fidelity report needs the shared capture" >&2
  exit 1
fi
cargo build --quiet --release --bin lidar-noise
python3 scripts/dev/fidelity/generate.py --bin target/release/lidar-noise \
  --capture ../shared/data/hdl32e/monterey.pcap --frames 2..4 \
  --refs docs/fidelity/references.json --out docs/fidelity.md
