#!/usr/bin/env bash
# The main job for now: build the release preset, then show the renderer at work — validate the
# three airlight methods against the shared reference vectors, chart the shipped low-beam
# headlamp, and render the default night-road scene (ego low beams, an oncoming car, street lamps,
# 100 m fog) to EXR and PNG. (`fogbeam serve` on the default scenario arrives with issue 5.)
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
cmake --preset release >/dev/null
cmake --build --preset release -j "$(nproc)"
mkdir -p out
./build/release/plugin/fogbeam validate --vectors tests/data/airlight_vectors.csv --out out/validate.csv
./build/release/plugin/fogbeam profile config/lamps/low_beam.ies --png out/low_beam.png
./build/release/plugin/fogbeam render --scene config/scenes/night_road.toml --out out/night_road.exr \
  --png out/night_road.png --exposure 1
echo "demo: wrote out/validate.csv, out/low_beam.png, out/night_road.exr and out/night_road.png"
