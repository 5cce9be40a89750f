#!/usr/bin/env bash
# The main job for now: build the release preset, then show the physics core at work —
# validate the three airlight methods against the shared reference vectors and chart the
# shipped low-beam headlamp. (`fogbeam serve` on the default scenario arrives with issue 5.)
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
cmake --preset release >/dev/null
cmake --build --preset release -j "$(nproc)"
mkdir -p out
./build/release/plugin/fogbeam validate --vectors tests/data/airlight_vectors.csv --out out/validate.csv
./build/release/plugin/fogbeam profile config/lamps/low_beam.ies --png out/low_beam.png
echo "demo: wrote out/validate.csv and out/low_beam.png"
