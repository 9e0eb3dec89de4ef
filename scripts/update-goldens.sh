#!/usr/bin/env bash
# Rewrites the regression goldens in tests/golden/ from the current build: the reports of
# `lidar-noise run` on the crossroad fixture with configs/paper.toml and seed 42.
# Run by hand after a deliberate change, then review `git diff tests/golden` before
# committing. Tests never call this.
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --quiet --bin lidar-noise
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
target/debug/lidar-noise --quiet run fixtures/crossroad.pcap -c configs/paper.toml --seed 42 --no-ply -o "$out"
for f in summary.json clusters.csv; do
  cp "$out/crossroad/$f" "tests/golden/crossroad_paper_$f"
done
git status --short tests/golden
