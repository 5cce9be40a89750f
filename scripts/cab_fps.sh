#!/usr/bin/env bash
# Frames per second of `fogbeam serve` on the built-in cab (its default scenario: oncoming
# traffic, the ego's lamps, street lamps; GL surfaces where EGL works) with its one channel at
# WIDTHxHEIGHT, free-running as fast as it can (timing.rate_hz = 1000), for SECONDS.
# Prints the service's status lines (every 5 s: frames, fps, frame p50/p95 and its surface and
# airlight parts); the first window includes start-up (view tables, shader compilation).
#
#   scripts/cab_fps.sh [WIDTHxHEIGHT] [SECONDS]     default 1280x720, 30 s
#
# Needs a release build (cmake --preset release && cmake --build --preset release).
set -euo pipefail
cd "$(dirname "$0")/.."
size="${1:-1280x720}"
seconds="${2:-30}"
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
exec ./build/release/plugin/fogbeam serve --config "$config" --duration "$seconds" --rate 1000 \
  --channel-prefix "fps-$$-" --udp-port 0 --status-port 0 2>&1 | grep --line-buffered "serve:"
