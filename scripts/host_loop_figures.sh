#!/usr/bin/env bash
# The cab loop's figures (docs/service.md, "Host depth"): the C host stand-in
# (ipc/examples/host_standin.c) against `fogbeam serve` with one depth_from channel, host depth
# published → overlay published (CLOCK_MONOTONIC on both sides), median and p95 after 10 warm-up
# frames, at 96×54, 640×360 and 1280×720, lock-step and free-running (host at 30 Hz, fogbeam at
# 60 Hz). The built-in cab's ego lamps and world (no scenario), CPU surfaces unused (no surface
# pass on a depth_from channel). Writes one JSON line per run and the last composite as a PNG.
#
#   scripts/host_loop_figures.sh [BUILD_DIR [OUT_DIR [FRAMES]]]   (build/release, /tmp/fogbeam-host-loop, 90)
set -euo pipefail
build=${1:-build/release}
out=${2:-/tmp/fogbeam-host-loop}
frames=${3:-90}
mkdir -p "$out"
fogbeam="$build/plugin/fogbeam"
standin="$build/ipc/fogbeam_host_standin"
tag="hl$$"
for size in 96x54 640x360 1280x720; do
  w=${size%x*}; h=${size#*x}
  for mode in lock-step free-running; do
    cfg="$out/serve-$size-$mode.toml"
    cat > "$cfg" <<TOML
[timing]
mode = "$mode"
rate_hz = 60

[status]
udp_port = 0

[input.udp]
port = 0

[[channel]]
name = "${tag}-overlay"
width = $w
height = $h
fov_x_deg = 60.0
format = "rgba16f-overlay"
depth_from = "${tag}-depth"
TOML
    "$fogbeam" serve --config "$cfg" --no-scenario > "$out/serve-$size-$mode.log" 2>&1 &
    serve=$!
    rate=0; [[ $mode == free-running ]] && rate=30
    "$standin" "${tag}-depth" "${tag}-overlay" "$w" "$h" "$frames" "$out/composite-$size-$mode.png" "$rate" 300 \
      || echo "host_loop_figures: $size $mode: the stand-in failed (see $out/serve-$size-$mode.log)" >&2
    kill -INT "$serve"; wait "$serve" || true
  done
done
