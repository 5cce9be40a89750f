#!/usr/bin/env bash
# The main job: build the release preset, then show the renderer and the cab service at work —
# validate the three airlight methods against the shared reference vectors, render the service's
# default scenario (oncoming traffic in 60 m fog, the ego dipping its high beams) headless with
# `fogbeam replay`, then run `fogbeam serve` on its built-in configuration (that same scenario on
# the default road, one 320x180 channel /fogbeam.main) for 30 s while the C host SDK's example
# reads frames from shared memory.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
cmake --preset release >/dev/null
cmake --build --preset release -j "$(nproc)"
mkdir -p out
./build/release/plugin/fogbeam validate --vectors tests/data/airlight_vectors.csv --out out/validate.csv
./build/release/plugin/fogbeam replay --scenario config/scenarios/oncoming_high_low.toml --out out/oncoming \
  --fps 2 --no-exr
./build/release/plugin/fogbeam serve --duration 30 --channel-prefix demo- --udp-port 0 --status-port 0 &
serve=$!
trap 'kill $serve 2>/dev/null || true' EXIT
./build/release/ipc/fogbeam_host_example demo-main 5 25   # 5 frames within 25 s, else exit 1
wait $serve
echo "demo: wrote out/validate.csv, out/oncoming/frame_*.png, out/oncoming/contact_sheet.png; serve ran 30 s"
