#!/usr/bin/env python3
"""`fogbeam replay` renders a scenario deterministically (issue 5).

Replays a scenario twice into two directories and requires byte-identical frames (EXR and PNG),
a contact sheet, frames.csv with one row per frame whose lights follow the scenario's events,
and timing.json. Also checks that a bad scenario is refused with its file and line.

usage: replay_deterministic.py FOGBEAM CONFIG SCENARIO
"""
import csv
import filecmp
import json
import os
import subprocess
import sys
import tempfile

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from fogbeam_scale import scaled  # noqa: E402

FOGBEAM, CONFIG, SCENARIO = sys.argv[1:4]
LOW, HIGH, POSITION = 0x2, 0x4, 0x1
# t = 0 … 5 s, FRAMES evenly: 11 (2 fps) at full size. FOGBEAM_TEST_SCALE renders fewer, at least
# 3 (0, 2.5, 5 s): every light phase of the scenario (low, high from 2 s, low from 4 s) keeps a frame.
FRAMES = scaled(11, 3)
FPS = (FRAMES - 1) / 5.0


def replay(out):
    r = subprocess.run([FOGBEAM, "replay", "--scenario", SCENARIO, "--config", CONFIG, "--out", out, "--fps", str(FPS),
                        "--end", "5"], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stdout + r.stderr
    return r.stdout


tmp = tempfile.mkdtemp(prefix="fogbeam-replay-")
a, b = os.path.join(tmp, "a"), os.path.join(tmp, "b")
print(replay(a))
replay(b)
frames = sorted(f for f in os.listdir(a) if f.startswith("frame_"))
assert len(frames) == 2 * FRAMES, frames  # t = 0, 0.5, …, 5 s: 11 frames at full size, EXR and PNG each
match, mismatch, errors = filecmp.cmpfiles(a, b, frames, shallow=False)
assert not mismatch and not errors, f"replays differ: {mismatch} {errors}"
assert os.path.getsize(os.path.join(a, "contact_sheet.png")) > 1000
with open(os.path.join(a, "frames.csv")) as f:
    rows = list(csv.DictReader(f))
assert len(rows) == FRAMES, rows
# tests/data/scenarios/timing.toml: low beam, high from 2 s, low again from 4 s.
expected = ["position+low-beam" if float(r["t_s"]) < 2 or float(r["t_s"]) >= 4 else "position+low-beam+high-beam"
            for r in rows]
assert [r["lights"] for r in rows] == expected, [r["lights"] for r in rows]
assert all(int(r["traffic"]) == 1 for r in rows), rows
timing = json.load(open(os.path.join(a, "timing.json")))
assert timing["frames"] == FRAMES and timing["frame_ms_median"] > 0, timing

bad = os.path.join(tmp, "bad.toml")
with open(bad, "w") as f:
    scene = os.path.abspath(os.path.join(os.path.dirname(SCENARIO), "../scenes/serve_world.toml"))
    f.write(open(SCENARIO).read().replace("../scenes/serve_world.toml", scene)
            .replace('lights = ["low-beam", "position"]', 'lights = ["low-beam", "headlight"]', 1))
r = subprocess.run([FOGBEAM, "replay", "--scenario", bad, "--config", CONFIG, "--out", os.path.join(tmp, "c")],
                   capture_output=True, text=True, timeout=60)
assert r.returncode == 2 and "bad.toml:" in r.stderr and "unknown light \"headlight\"" in r.stderr, r.stderr
print(f"replay: {FRAMES} frames twice, byte-identical (EXR and PNG); frames.csv lights follow the events; bad file: {r.stderr.strip()}")
