#!/usr/bin/env python3
"""`fogbeam view` under Xvfb (issue 5): screenshots compared with the frames published.

A test writer (view_test_writer.cpp) publishes a known 4 x 2 patch pattern into shared-memory
channels; `fogbeam view --screenshot` saves its window after a few frames, and every patch's
centre in the screenshot must show the display value of the pixel published there, read back with
the Python reader (docs/shm.md): sRGB(Reinhard(2^EV * L)) for linear layers (the mapping of
fogbeam::toneMapSrgb8), round(255 * T) for the transmittance, the bytes themselves for RGBA8 sRGB.
Tolerance: 2/255 (the GPU's pow against numpy's).

The exposure of linear layers is automatic unless --exposure gives an EV: the viewer prints the EV
of its screenshot, which must be the rule of fogbeam/render/exposure.hpp applied to the frame
(the 99.5th percentile of Rec. 709 luminance shown at x = 4: EV = log2(4 / L), clamped to
[-16, 6]; within 0.1 EV, the histogram's bin), and the screenshot must show the frame at it.

Cases (one ctest each):
  overlay_layers   RGBA16F overlay: airlight at +1 EV, composite (falls back to the airlight) at
                   the automatic EV, transmittance with the stats overlay (text must be drawn, top
                   left)
  tiled_channels   three channels side by side (overlay, RGBA8, RGBA16F linear at -1 EV)
  writer_restart   the writer closes and another starts (new generation, new pattern): the viewer
                   attaches again and shows the new frames
  writer_killed    the same with a writer killed by SIGKILL (its segment left behind, stale)
  keys             1/2/3, +/- (automatic off), S, Tab typed with xdotool (skipped without it); A
                   turns the automatic exposure on after --exposure 1; Q quits
  timeout_unknown_channel  no such channel: exit 1 with a message after --timeout
  no_display       no DISPLAY: exit 2 with "no display"

usage: view_screenshot.py FOGBEAM TEST_WRITER READER_DIR OUT_DIR CASE
Exit 77 (ctest: skipped) when Xvfb is not installed.
"""
import os
import shutil
import subprocess
import sys
import time

import numpy as np

FOGBEAM, WRITER, READER_DIR, OUT_DIR, CASE = sys.argv[1:6]
sys.path.insert(0, READER_DIR)
from fogbeam_reader import FogbeamReader  # noqa: E402

try:
    from PIL import Image
except ImportError:
    raise SystemExit("python3-pil is missing (scripts/setup.sh installs it)")

TOLERANCE = 2  # 8-bit display levels
os.makedirs(OUT_DIR, exist_ok=True)
failures = []


def check(cond, what):
    print(("ok   " if cond else "FAIL ") + what)
    if not cond:
        failures.append(what)


def start_xvfb():
    """Xvfb on a free display (-displayfd writes the number it took)."""
    if shutil.which("Xvfb") is None:
        print("SKIP: Xvfb is not installed (Debian package xvfb; scripts/setup.sh installs it)")
        sys.exit(77)
    r, w = os.pipe()
    proc = subprocess.Popen(["Xvfb", "-displayfd", str(w), "-screen", "0", "1600x1200x24", "-nolisten", "tcp"],
                            pass_fds=(w,), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    os.close(w)
    with os.fdopen(r) as f:
        number = f.readline().strip()
    if not number:
        raise SystemExit(f"Xvfb did not start: {proc.stderr.read().decode(errors='replace')}")
    return proc, f":{number}"


def view_env(display):
    env = dict(os.environ)
    env.pop("WAYLAND_DISPLAY", None)
    if display is None:
        env.pop("DISPLAY", None)
    else:
        env["DISPLAY"] = display
    return env


def channel_name(tag):
    return f"ctest-view-{os.getpid()}-{tag}"


def start_writer(channel, fmt, width, height, rate=30, frames=0, variant=0):
    return subprocess.Popen([WRITER, channel, fmt, str(width), str(height), str(rate), str(frames), str(variant)],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)


def published(channel, not_generation=None):
    """The pixels of the newest frame of `channel` (height x width x 4, uint8 or float32), from a
    writer whose generation is not `not_generation` (a killed writer's segment stays behind)."""
    end = time.monotonic() + 10
    while True:
        try:
            reader = FogbeamReader(channel)
            if reader.generation == not_generation:
                reader.close()
                raise FileNotFoundError(channel)
            while True:
                got = reader.latest()
                if got is not None:
                    _, pixels = got
                    reader.close()
                    return pixels.astype(np.float32) if pixels.dtype == np.float16 else pixels
                if time.monotonic() > end:
                    raise SystemExit(f"no frame on {channel}")
                time.sleep(0.02)
        except (FileNotFoundError, ValueError):
            if time.monotonic() > end:
                raise SystemExit(f"channel {channel} did not appear")
            time.sleep(0.02)


def tonemap8(linear, ev):
    """fogbeam::toneMapSrgb8: x = L 2^EV, Reinhard, sRGB transfer, 8 bits."""
    x = np.maximum(np.asarray(linear, dtype=np.float64) * 2.0 ** ev, 0.0)
    lin = x / (1.0 + x)
    s = np.where(lin <= 0.0031308, 12.92 * lin, 1.055 * lin ** (1 / 2.4) - 0.055)
    return np.clip(np.rint(255 * s), 0, 255)


def auto_ev(frame):
    """The automatic exposure of fogbeam/render/exposure.hpp for the RGB of `frame`, exact
    percentile (the viewer's histogram is within 0.1 EV of it)."""
    rgb = np.asarray(frame[..., :3], dtype=np.float32)
    y = 0.2126 * rgb[..., 0] + 0.7152 * rgb[..., 1] + 0.0722 * rgb[..., 2]
    ref = float(np.percentile(y, 99.5))
    return float(np.clip(np.log2(4.0 / ref), -16.0, 6.0)) if ref > 0 else 6.0


def shown_ev(output, mode):
    """The EV the viewer printed with its screenshot, and that it was `mode` (auto | fixed)."""
    for line in output.splitlines():
        if "exposure" in line and line.startswith("fogbeam view: wrote"):
            words = line.split("exposure ")[1].split()
            check(words[2] == f"({mode})", f"exposure {mode}: {line}")
            return float(words[0])
    check(False, "the viewer printed its exposure")
    return 0.0


def run_view(display, args, timeout=60):
    proc = subprocess.run([FOGBEAM, "view", *args], env=view_env(display), stdout=subprocess.PIPE,
                          stderr=subprocess.PIPE, text=True, timeout=timeout)
    print(f"$ fogbeam view {' '.join(args)}  -> exit {proc.returncode}")
    for line in (proc.stdout + proc.stderr).splitlines():
        print("  | " + line)
    return proc


def screenshot(display, channels, out, extra, after=3, output=False):
    path = os.path.join(OUT_DIR, out)
    if os.path.exists(path):
        os.remove(path)
    proc = run_view(display, ["--channel", ",".join(channels), "--screenshot", path, "--after-frames", str(after),
                              "--timeout", "20", *extra])
    check(proc.returncode == 0 and os.path.exists(path), f"{out}: view exited 0 and wrote the screenshot")
    if not os.path.exists(path):
        raise SystemExit(1)
    shot = np.asarray(Image.open(path).convert("RGB")).astype(np.int32)
    return (shot, path, proc.stdout) if output else (shot, path)


def patch_centres(width, height):
    """(patch index, x, y) of each patch centre, frame pixels; patch = 4 row + column."""
    return [(4 * row + col, (2 * col + 1) * width // 8, (2 * row + 1) * height // 4) for row in range(2) for col in range(4)]


def compare(shot, path, x0, frame, expect_of, what, rows=(0, 1)):
    """Every patch centre of `frame` (drawn at native size with its left edge at x0) against
    expect_of(published pixel) in a 5 x 5 block."""
    h, w = frame.shape[:2]
    for p, x, y in patch_centres(w, h):
        if p // 4 not in rows:
            continue
        expected = expect_of(frame[y, x])
        block = shot[y - 2:y + 3, x0 + x - 2:x0 + x + 3]
        err = int(np.abs(block - expected[None, None, :]).max())
        check(err <= TOLERANCE, f"{what}: patch {p} at ({x0 + x}, {y}) expected {expected.astype(int).tolist()}, "
                                f"got {block[2, 2].tolist()} (max error {err}) [{path}]")


def grey(px):
    return np.full(3, np.rint(255 * np.clip(px[3], 0, 1)))


def case_overlay_layers(display):
    ch = channel_name("overlay")
    W, H = 384, 216
    writer = start_writer(ch, "rgba16f-overlay", W, H)
    try:
        frame = published(ch)
        shot, path = screenshot(display, [ch], "overlay_airlight.png", ["--layer", "airlight", "--exposure", "1",
                                                                        "--no-stats"])
        check(shot.shape[:2] == (H, W), f"window at the frame's native size {W}x{H}: {shot.shape[1]}x{shot.shape[0]}")
        compare(shot, path, 0, frame, lambda px: tonemap8(px[:3], 1.0), "airlight +1 EV")

        shot, path, out = screenshot(display, [ch], "overlay_composite.png", ["--layer", "composite", "--no-stats"],
                                     output=True)
        ev = shown_ev(out, "auto")
        want = auto_ev(frame)
        check(abs(ev - want) <= 0.1, f"automatic exposure {ev:+.3f} EV, the rule's {want:+.3f} EV")
        compare(shot, path, 0, frame, lambda px: tonemap8(px[:3], ev), f"composite falls back to the airlight, auto {ev:+.2f} EV")

        shot, path = screenshot(display, [ch], "overlay_transmittance_stats.png", ["--layer", "transmittance"])
        # The stats box covers the top rows; the bottom row's patch centres stay clear.
        compare(shot, path, 0, frame, grey, "transmittance grey = T", rows=(1,))
        # Text: white pixels inside the stats box, top left, where the frame is a darker grey.
        box = shot[4:48, 4:200]
        white = int((box.min(axis=2) >= 240).sum())
        check(white >= 100, f"stats overlay drawn: {white} white text pixels in the top-left box (want >= 100)")
        # Without the stats the same box holds the frame only.
        shot, path = screenshot(display, [ch], "overlay_transmittance.png", ["--layer", "transmittance", "--no-stats"])
        compare(shot, path, 0, frame, grey, "transmittance grey = T, no stats")
        white = int((shot[4:48, 4:200].min(axis=2) >= 240).sum())
        check(white == 0, f"--no-stats draws no text: {white} white pixels in the top-left box")
    finally:
        writer.terminate()
        writer.wait(10)


def case_tiled_channels(display):
    W, H = 256, 144
    names = [channel_name("tile-overlay"), channel_name("tile-rgba8"), channel_name("tile-linear")]
    writers = [start_writer(names[0], "rgba16f-overlay", W, H), start_writer(names[1], "rgba8-srgb", W, H),
               start_writer(names[2], "rgba16f-linear", W, H)]
    try:
        frames = [published(n) for n in names]
        shot, path = screenshot(display, names, "tiled.png", ["--layer", "transmittance", "--exposure", "-1",
                                                              "--no-stats"])
        check(shot.shape[:2] == (H, 3 * W), f"three tiles side by side: {shot.shape[1]}x{shot.shape[0]} (want {3 * W}x{H})")
        compare(shot, path, 0, frames[0], grey, "tile 1 (overlay): transmittance")
        compare(shot, path, W, frames[1], lambda px: np.asarray(px[:3], dtype=np.float64),
                "tile 2 (RGBA8 sRGB): composite as published")
        compare(shot, path, 2 * W, frames[2], lambda px: tonemap8(px[:3], -1.0), "tile 3 (RGBA16F linear): composite -1 EV")
    finally:
        for w in writers:
            w.terminate()
            w.wait(10)


def restart(display, tag, stop_first):
    """The viewer first (it waits for the channel), then a writer that goes (stop_first), then a
    new one with another pattern: 25 new frames are more than the first writer publishes."""
    ch = channel_name(tag)
    W, H = 256, 144
    path = os.path.join(OUT_DIR, f"{tag}.png")
    if os.path.exists(path):
        os.remove(path)
    view = subprocess.Popen([FOGBEAM, "view", "--channel", ch, "--layer", "transmittance", "--no-stats", "--screenshot",
                             path, "--after-frames", "25", "--timeout", "30"], env=view_env(display),
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        time.sleep(0.5)
        gone = stop_first(ch, W, H)
        second = start_writer(ch, "rgba16f-overlay", W, H, rate=20, variant=1)
        try:
            frame = published(ch, not_generation=gone)
            out, _ = view.communicate(timeout=40)
        finally:
            second.terminate()
            second.wait(10)
    finally:
        if view.poll() is None:
            view.kill()
            view.wait()
    print("  | " + out.replace("\n", "\n  | "))
    check(view.returncode == 0 and os.path.exists(path), "view exited 0 with its screenshot")
    check(out.count("attached /fogbeam." + ch) == 2, "view attached twice (once per writer, not to the old segment)")
    check(out.count("writer gone") == 1, "view noticed the first writer go, once")
    if os.path.exists(path):
        shot = np.asarray(Image.open(path).convert("RGB")).astype(np.int32)
        compare(shot, path, 0, frame, grey, "after the restart: the second writer's transmittance (1 - T)")


def case_writer_restart(display):
    def close_cleanly(ch, W, H):
        first = start_writer(ch, "rgba16f-overlay", W, H, rate=10, frames=10, variant=0)
        first.wait(20)
        check(first.returncode == 0, "first writer published 10 frames and closed the channel")
        return None  # the segment is unlinked
    restart(display, "restart", close_cleanly)


def case_writer_killed(display):
    def kill(ch, W, H):
        first = start_writer(ch, "rgba16f-overlay", W, H, rate=10, variant=0)
        published(ch)
        reader = FogbeamReader(ch)
        generation = reader.generation
        reader.close()
        time.sleep(0.5)
        first.kill()  # SIGKILL: the segment stays, with a dead pid, until the next writer replaces it
        first.wait(10)
        check(os.path.exists(f"/dev/shm/fogbeam.{ch}"), "the killed writer's segment is left behind")
        time.sleep(1.0)  # the viewer must not attach to it again meanwhile
        return generation
    restart(display, "killed", kill)


def xdotool(display, *args):
    proc = subprocess.run(["xdotool", *args], env=view_env(display), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                          text=True, timeout=20)
    if proc.returncode != 0:
        raise SystemExit(f"xdotool {' '.join(args)}: exit {proc.returncode}: {proc.stderr.strip()}")
    return proc.stdout


def case_keys(display):
    """Keys typed before the first frame (xdotool), so that the screenshot is after them."""
    if shutil.which("xdotool") is None:
        print("SKIP: xdotool is not installed (Debian package xdotool; scripts/setup.sh installs it)")
        sys.exit(77)
    W, H = 256, 144
    names = [channel_name("keys-overlay"), channel_name("keys-rgba8")]
    path = os.path.join(OUT_DIR, "keys.png")
    if os.path.exists(path):
        os.remove(path)
    view = subprocess.Popen([FOGBEAM, "view", "--channel", ",".join(names), "--no-stats", "--screenshot", path,
                             "--after-frames", "3", "--timeout", "30"], env=view_env(display),
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    writers = []
    try:
        # --onlyvisible: GLFW names the window before it maps it, and focusing an unmapped window
        # is an X error (BadMatch).
        window = xdotool(display, "search", "--sync", "--onlyvisible", "--name", "^fogbeam view: " + names[0]).split()[0]
        xdotool(display, "windowfocus", "--sync", window)
        # 3 then 2: airlight; + + -: +0.5 EV (by hand: the automatic exposure off); S: stats on;
        # Tab: the first channel alone.
        for key in ("3", "2", "plus", "plus", "minus", "s", "Tab"):
            xdotool(display, "key", "--window", window, key)
        time.sleep(0.3)  # the viewer handles them on its next turn (every 5 ms)
        writers = [start_writer(names[0], "rgba16f-overlay", W, H), start_writer(names[1], "rgba8-srgb", W, H)]
        frame = published(names[0])
        out, _ = view.communicate(timeout=40)
    finally:
        if view.poll() is None:
            view.kill()
            view.wait()
        for w in writers:
            w.terminate()
            w.wait(10)
    print("  | " + out.replace("\n", "\n  | "))
    check(view.returncode == 0 and os.path.exists(path), "view exited 0 with its screenshot")
    if not os.path.exists(path):
        return
    shot = np.asarray(Image.open(path).convert("RGB")).astype(np.int32)
    check(shot.shape[:2] == (H, 2 * W), f"window holds both channels' native sizes: {shot.shape[1]}x{shot.shape[0]}")
    # Tab: the first channel alone, fitted and centred in the whole window.
    x0 = (shot.shape[1] - W) // 2
    compare(shot, path, x0, frame, lambda px: tonemap8(px[:3], 0.5), "keys 3 2 + + - S Tab: airlight +0.5 EV", rows=(1,))
    shown_ev(out, "fixed")
    check(int(np.abs(shot[H // 2:H - 30, 4:x0 - 4] - 13).max()) <= 2, "beside the focused channel: background only")
    white = int((shot[4:48, 4:200].min(axis=2) >= 240).sum())
    check(white >= 100, f"S turned the stats on: {white} white text pixels top left")

    # A after --exposure 1: the automatic exposure on (the frame's own EV: none was shown yet).
    ch = channel_name("keys-auto")
    path = os.path.join(OUT_DIR, "keys_auto.png")
    if os.path.exists(path):
        os.remove(path)
    view = subprocess.Popen([FOGBEAM, "view", "--channel", ch, "--no-stats", "--exposure", "1", "--screenshot", path,
                             "--after-frames", "3", "--timeout", "30"], env=view_env(display),
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    writer = None
    try:
        window = xdotool(display, "search", "--sync", "--onlyvisible", "--name", "^fogbeam view: " + ch).split()[0]
        xdotool(display, "windowfocus", "--sync", window)
        xdotool(display, "key", "--window", window, "a")
        time.sleep(0.3)
        writer = start_writer(ch, "rgba16f-linear", W, H)
        frame = published(ch)
        out, _ = view.communicate(timeout=40)
    finally:
        if view.poll() is None:
            view.kill()
            view.wait()
        if writer is not None:
            writer.terminate()
            writer.wait(10)
    print("  | " + out.replace("\n", "\n  | "))
    check(view.returncode == 0 and os.path.exists(path), "view exited 0 with its screenshot")
    if os.path.exists(path):
        ev, want = shown_ev(out, "auto"), auto_ev(frame)
        check(abs(ev - want) <= 0.1 and abs(ev - 1.0) > 0.5, f"A: automatic exposure {ev:+.3f} EV, the rule's {want:+.3f} EV")
        shot = np.asarray(Image.open(path).convert("RGB")).astype(np.int32)
        compare(shot, path, 0, frame, lambda px: tonemap8(px[:3], ev), f"A: composite at auto {ev:+.2f} EV")

    # Q quits: exit 0 without a screenshot.
    ch = channel_name("keys-quit")
    writer = start_writer(ch, "rgba16f-overlay", W, H)
    try:
        published(ch)
        view = subprocess.Popen([FOGBEAM, "view", "--channel", ch, "--timeout", "30"], env=view_env(display),
                                stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        window = xdotool(display, "search", "--sync", "--onlyvisible", "--name", "^fogbeam view: " + ch).split()[0]
        xdotool(display, "windowfocus", "--sync", window)
        # Press only: the viewer quits on the press, and a release sent to its closed window would
        # be an X error (BadWindow) in xdotool.
        xdotool(display, "keydown", "--window", window, "q")
        try:
            view.communicate(timeout=10)
        except subprocess.TimeoutExpired:
            view.kill()
            view.wait()
        check(view.returncode == 0, f"Q quits with status 0 (got {view.returncode})")
    finally:
        writer.terminate()
        writer.wait(10)


def case_timeout_unknown_channel(display):
    ch = channel_name("nosuch")
    t0 = time.monotonic()
    proc = run_view(display, ["--channel", ch, "--timeout", "1.5", "--screenshot", os.path.join(OUT_DIR, "never.png")])
    took = time.monotonic() - t0
    check(proc.returncode == 1, f"exit status 1 (got {proc.returncode})")
    check(f"no new frame from /fogbeam.{ch} within 1.5 s" in proc.stderr, "message names the channel and the timeout")
    check(1.4 <= took <= 15, f"gave up after the timeout ({took:.1f} s)")


def case_no_display(_display):
    proc = run_view(None, ["--channel", channel_name("nodisplay"), "--timeout", "5"])
    check(proc.returncode == 2, f"exit status 2 (got {proc.returncode})")
    check("fogbeam view: no display (set DISPLAY or run under xvfb-run)" in proc.stderr, "clear 'no display' message")


def main():
    cases = {f.__name__[len("case_"):]: f for f in (case_overlay_layers, case_tiled_channels, case_writer_restart, case_writer_killed,
                                                   case_keys,
                                                   case_timeout_unknown_channel, case_no_display)}
    if CASE not in cases:
        raise SystemExit(f"unknown case {CASE}; one of {', '.join(cases)}")
    xvfb, display = (None, None) if CASE == "no_display" else start_xvfb()
    try:
        cases[CASE](display)
    finally:
        if xvfb is not None:
            xvfb.terminate()
            xvfb.wait(10)
    if failures:
        print(f"{len(failures)} check(s) failed")
        return 1
    print("all checks passed")
    return 0


if __name__ == "__main__":
    sys.exit(main())
