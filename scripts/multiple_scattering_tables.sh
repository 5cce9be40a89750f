#!/usr/bin/env bash
# Regenerates the shipped multiple-scattering tables (config/multiple_scattering/*.msc, embedded in
# the library at build time; docs/physics.md, "Multiple scattering tables") with `fogbeam tables`.
# Deterministic: the same binary, paths and seed write the same files on any number of threads.
# About 7–19 minutes per table on a 2-core machine (80 000 paths, 286 lamp nodes, 8 albedos, emission bins).
# Then the ground's factor on each (`fogbeam tables --ground`, *.gnd; fogbeam/physics/ground_correction.hpp),
# 20 000 paths per node, ~4.5 minutes each on 2 cores; it reads the embedded tables, so rebuild
# fogbeam between the two when the tables changed.
#   scripts/multiple_scattering_tables.sh [build/release/plugin/fogbeam] [paths] [ground paths]
set -euo pipefail
cd "$(dirname "$0")/.."
fogbeam=${1:-build/release/plugin/fogbeam}
paths=${2:-80000}
ground_paths=${3:-20000}
out=config/multiple_scattering
mkdir -p "$out"
for g in 0.75 0.80 0.85 0.90; do
  "$fogbeam" tables --phase henyey-greenstein --g "$g" --paths "$paths" --out "$out/hg-$(printf '%.3f' "$g").msc"
done
"$fogbeam" tables --phase fog-mie --droplet-diameter 10 --paths "$paths" --out "$out/fog-mie-10.0um.msc"
for g in 0.75 0.80 0.85 0.90; do
  "$fogbeam" tables --ground --phase henyey-greenstein --g "$g" --paths "$ground_paths" \
    --out "$out/hg-$(printf '%.3f' "$g").gnd"
done
"$fogbeam" tables --ground --phase fog-mie --droplet-diameter 10 --paths "$ground_paths" --out "$out/fog-mie-10.0um.gnd"
