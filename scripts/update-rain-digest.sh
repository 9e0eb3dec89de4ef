#!/usr/bin/env bash
# Rewrites tests/golden/rain_goodin_digest.txt: for the three fixtures and (when present)
# frames 2-4 of ../shared/data/hdl32e/monterey.pcap, with configs/paper.toml and
# configs/rain.toml (Goodin rain), an xxh3 of every return's range, power, fate and cause.
# Run by hand only to record a deliberate change, then review `git diff tests/golden`.
# Tests never call this; `cargo test --test weather_physics` compares with the file.
set -euo pipefail
cd "$(dirname "$0")/.."
RAIN_DIGEST_WRITE=1 cargo test --quiet --test weather_physics -- --ignored --exact write_goodin_digest
git status --short tests/golden
