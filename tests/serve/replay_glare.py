#!/usr/bin/env python3
"""`fogbeam replay` with glow and glare on (issue 7): the per-frame figures in frames.csv.

Replays tests/data/scenarios/timing.toml (an oncoming car closing from 150 m to 30 m at 40 m/s in
80 m fog) with `--set glow.enabled=true --set glare.enabled=true`, and requires frames.csv's four
extra columns (docs/scenario.md), effects_lamps.csv with the car's lamp in every frame, its eye
illuminance rising as it approaches and equal to I e^(-K_t R) / R^2 of its own row, a veiling
luminance > 0, and timing.json's glow/glare figures. Without the settings the columns are absent.

usage: replay_glare.py FOGBEAM CONFIG SCENARIO
"""
import csv
import json
import math
import os
import subprocess
import sys
import tempfile

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from fogbeam_scale import scaled  # noqa: E402

FOGBEAM, CONFIG, SCENARIO = sys.argv[1:4]
EXTRA = ["eye_illuminance_lx", "veiling_luminance_cd_m2", "glow_ms", "glare_ms"]
KT = math.log(20.0) / 80.0  # the scenario's fog: visibility 80 m
# t = 0 … 3 s, FRAMES evenly: 4 (1 fps) at full size. FOGBEAM_TEST_SCALE renders fewer, at least
# 2 (0 and 3 s, the car at 146 m and 26 m): the eye illuminance must still rise from frame to frame.
FRAMES = scaled(4, 2)
FPS = (FRAMES - 1) / 3.0


def replay(out, *settings):
    args = [FOGBEAM, "replay", "--scenario", SCENARIO, "--config", CONFIG, "--out", out, "--fps", str(FPS), "--end", "3",
            "--no-exr", "--no-png"]
    for s in settings:
        args += ["--set", s]
    r = subprocess.run(args, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stdout + r.stderr
    return r.stdout


def rows(path):
    with open(path) as f:
        return list(csv.DictReader(f))


tmp = tempfile.mkdtemp(prefix="fogbeam-replay-glare-")
on, off = os.path.join(tmp, "on"), os.path.join(tmp, "off")
summary = replay(on, "glow.enabled=true", "glare.enabled=true")
assert "glow on, glare on" in summary and "glow / glare" in summary, summary
frames = rows(os.path.join(on, "frames.csv"))
assert len(frames) == FRAMES, frames
assert all(k in frames[0] for k in EXTRA), list(frames[0])
lamps = [r for r in rows(os.path.join(on, "effects_lamps.csv")) if r["lamp"] == "left low beam"]
assert [int(r["frame"]) for r in lamps] == list(range(FRAMES)), lamps
previous = 0.0
for r, f in zip(lamps, frames):
    e, i, d = float(r["eye_illuminance_lx"]), float(r["intensity_cd"]), float(r["distance_m"])
    assert e > previous, (r, previous)
    assert abs(e - i * math.exp(-KT * d) / (d * d)) <= 1e-4 * e, r  # the CSV holds 6 digits
    assert float(f["eye_illuminance_lx"]) >= e * (1 - 1e-9), (f, r)  # the sum holds the car's lamp
    assert float(f["veiling_luminance_cd_m2"]) > 0.0, f
    assert float(f["glow_ms"]) >= 0.0 and float(f["glare_ms"]) > 0.0, f
    previous = e
timing = json.load(open(os.path.join(on, "timing.json")))
assert timing["eye_illuminance_lx_max"] > 0 and timing["glare_ms_median"] > 0, timing

replay(off)
plain = rows(os.path.join(off, "frames.csv"))
assert len(plain) == FRAMES and not any(k in plain[0] for k in EXTRA), list(plain[0])
assert not os.path.exists(os.path.join(off, "effects_lamps.csv"))
print("replay with glow and glare: car's eye illuminance per frame " +
      ", ".join(f"{float(r['eye_illuminance_lx']):.3g} lx at {float(r['distance_m']):.0f} m" for r in lamps) +
      "; veiling at the centre " + ", ".join(f"{float(f['veiling_luminance_cd_m2']):.3g}" for f in frames) + " cd/m2")
