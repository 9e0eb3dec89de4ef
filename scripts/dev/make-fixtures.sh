#!/usr/bin/env bash
# Regenerates the synthetic fixtures under fixtures/ with `lidar-noise synth`.
# Run by hand after changing the synthesizer or a preset; never run by tests or CI.
set -euo pipefail
cd "$(dirname "$0")/../.."
mkdir -p fixtures
cargo run --release --quiet -- synth --preset crossroad -o fixtures
cargo run --release --quiet -- synth --preset parking -o fixtures
cargo run --release --quiet -- synth --preset empty -o fixtures
du -b fixtures/crossroad.* fixtures/parking.* fixtures/empty.*
