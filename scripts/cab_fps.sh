#!/usr/bin/env bash
# Frames per second of `fogbeam serve` on the built-in cab (its default scenario: oncoming
# traffic, the ego's lamps, street lamps; GL surfaces where EGL works) with its one channel at
# WIDTHxHEIGHT, free-running as fast as it can (timing.rate_hz = 1000), for SECONDS.
# Prints the service's status lines (every 5 s: frames, fps, frame p50/p95 and its surface and
# airlight parts); the first window includes start-up (view tables, shader compilation).
#
# OVERLAP (auto, on, off; default auto) sets [render] overlap_frames: "on" runs the surface pass of
# frame N+1 beside the rest of frame N (docs/service.md, "Overlapped frames"), "off" in sequence;
# compare the two alternately in one session (this machine's speed drifts by ±20 %).
#
#   scripts/cab_fps.sh [WIDTHxHEIGHT] [SECONDS] [OVERLAP]    default 1280x720, 30 s, auto
#
# Needs a release build (cmake --preset release && cmake --build --preset release); FOGBEAM
# names another binary.
set -euo pipefail
cd "$(dirname "$0")/.."
size="${1:-1280x720}"
seconds="${2:-30}"
overlap="${3:-auto}"
case "$overlap" in auto | on | off) ;; *) echo "cab_fps.sh: OVERLAP is auto, on or off, not '$overlap'" >&2; exit 2 ;; esac
fogbeam="${FOGBEAM:-./build/release/plugin/fogbeam}"
width="${size%x*}"
height="${size#*x}"
config="$(mktemp --suffix=.toml)"
trap 'rm -f "$config"' EXIT
# One [[channel]] replaces the built-in one whole (docs/service.md, "Layers").
cat > "$config" <<EOF
[[channel]]
name = "main"
width = $width
height = $height
fov_x_deg = 60.0
format = "rgba8-srgb"
EOF
exec "$fogbeam" serve --config "$config" --duration "$seconds" --rate 1000 --overlap "$overlap" \
  --channel-prefix "fps-$$-" --udp-port 0 --status-port 0 2>&1 | grep --line-buffered "serve:"
