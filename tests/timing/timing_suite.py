#!/usr/bin/env python3
"""Headless frame-timing suite (issue 5; ctest label "timing").

Starts `fogbeam serve` on a test cab (free-running at 60 Hz), drives it with `fogbeam send`
playing a scenario at 60 Hz over UDP, reads every frame it can through the host SDK's Python
reader (docs/shm.md), and checks each frame's metadata against what `fogbeam send` logged:
  - frame numbers strictly increase;
  - the ego pose (yaw, pitch, roll) and lamp state equal those of the ego message the frame
    says it used (ego_sequence), and the lamp state that of the lamp message (lamp_sequence);
  - the oncoming car is in the frame (traffic_count) while the scenario has it.
It asks the service for its status over UDP once during the run, then prints frame-time and
input-to-frame latency percentiles (the service's own per-frame figures and the reader's view:
publish → read), frames published vs the 60 Hz schedule, and stops the service with SIGTERM.

Figures are printed, not judged: a slow or loaded machine gives slower frames, not a failure.

usage: timing_suite.py FOGBEAM CONFIG SCENARIO READER_DIR
"""
import csv
import json
import os
import signal
import subprocess
import sys
import tempfile
import time

sys.path.insert(0, sys.argv[4])
sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "serve"))
from fogbeam_testlib import attach, free_port, request_status, start_serve  # noqa: E402

FOGBEAM, CONFIG, SCENARIO = sys.argv[1], sys.argv[2], sys.argv[3]
DURATION_S = 6.0


def pct(values, q):
    if not values:
        return float("nan")
    v = sorted(values)
    return v[min(len(v) - 1, int(q * len(v)))]


def main():
    prefix = f"ctest-timing-{os.getpid()}-"
    channel = prefix + "main"
    port, status_port = free_port(), free_port()
    tmp = tempfile.mkdtemp(prefix="fogbeam-timing-")
    sent_log = os.path.join(tmp, "sent.csv")
    serve = start_serve(FOGBEAM, CONFIG, prefix, port, status_port)
    send = None
    try:
        reader = attach(channel, serve, first_frame=True)
        send = subprocess.Popen([FOGBEAM, "send", "--scenario", SCENARIO, "--to", f"127.0.0.1:{port}", "--rate", "60",
                                 "--log", sent_log], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        frames, read_lag_ms = [], []
        last = None
        status = None
        t_end = time.monotonic() + DURATION_S + 10
        while send.poll() is None and time.monotonic() < t_end:
            got = reader.latest()
            if got is not None and got[0]["frame"] != last:
                meta = got[0]
                now_ns = time.clock_gettime_ns(time.CLOCK_MONOTONIC)
                read_lag_ms.append((now_ns - meta["publish_ns"]) / 1e6)
                frames.append(meta)
                last = meta["frame"]
            if status is None and len(frames) > 60:
                status = request_status(status_port)
            time.sleep(0.001)
        send_out, _ = send.communicate(timeout=30)
        assert send.returncode == 0, f"fogbeam send failed: {send_out}"
        time.sleep(0.2)
        reader.close()

        with open(sent_log) as f:
            sent = list(csv.DictReader(f))
        by_ego = {int(r["ego_sequence"]): r for r in sent}
        by_lamp = {int(r["lamp_sequence"]): r for r in sent}
        seqs = sorted(by_ego)
        # Frames made from this run's input (the first frames precede it).
        checked = [m for m in frames if m["ego_sequence"] in by_ego]
        assert len(checked) > 30, f"only {len(checked)} frames carried an ego message of this run"
        for a, b in zip(frames, frames[1:]):
            assert b["frame"] > a["frame"], f"frame numbers do not increase: {a['frame']} then {b['frame']}"
        light_changes = set()
        for m in checked:
            e = by_ego[m["ego_sequence"]]
            assert abs(m["yaw_deg"] - float(e["yaw_deg"])) < 1e-3, (m, e)
            assert abs(m["pitch_deg"] - float(e["pitch_deg"])) < 1e-3 and abs(m["roll_deg"] - float(e["roll_deg"])) < 1e-3
            lamp = by_lamp.get(m["lamp_sequence"])
            assert lamp is not None, f"frame {m['frame']}: lamp sequence {m['lamp_sequence']} was never sent"
            assert m["lights"] == int(lamp["lights"]), (m, lamp)
            # Each state goes out as environment, lamps, traffic, ego: a frame's lamp state is its
            # ego message's own (ego − 2) or, when the next state is half applied, the next (ego + 2).
            assert m["lamp_sequence"] in (m["ego_sequence"] - 2, m["ego_sequence"] + 2), m
            assert m["traffic_count"] == int(e["traffic"]) == 1, (m, e)
            light_changes.add(m["lights"])
        assert len(light_changes) >= 2, f"the low → high → low switching was not seen: {light_changes}"
        assert status is not None and status["frames"] > 0 and "udp" in status, status

        serve.send_signal(signal.SIGTERM)
        out, _ = serve.communicate(timeout=30)
        assert serve.returncode == 0, f"serve exited {serve.returncode}: {out}"
        assert not os.path.exists(f"/dev/shm/fogbeam.{channel}"), "segment not unlinked on SIGTERM"

        run = [m for m in frames if m["ego_sequence"] in by_ego]
        span_s = (run[-1]["publish_ns"] - run[0]["publish_ns"]) / 1e9
        published = run[-1]["frame"] - run[0]["frame"] + 1
        total = [m["total_ms"] for m in run]
        latency = [m["latency_ms"] for m in run]
        print(f"timing suite: {len(sent)} states sent at 60 Hz; {published} frames published in {span_s:.2f} s "
              f"({published / span_s:.1f} fps; the schedule asks for 60), {len(run)} read and checked "
              f"(pose, lights, lamp and ego sequence numbers, traffic), {len(light_changes)} light states seen")
        print(f"  frame time (render, service)      p50 {pct(total, 0.5):6.2f} ms  p95 {pct(total, 0.95):6.2f} ms  "
              f"max {max(total):6.2f} ms")
        print(f"  input to publish (service)        p50 {pct(latency, 0.5):6.2f} ms  p95 {pct(latency, 0.95):6.2f} ms  "
              f"max {max(latency):6.2f} ms")
        print(f"  publish to read (host reader)     p50 {pct(read_lag_ms, 0.5):6.2f} ms  p95 {pct(read_lag_ms, 0.95):6.2f} ms")
        print(f"  status over UDP: {json.dumps(status)}")
    except BaseException:
        for p in (send, serve):
            if p is not None and p.poll() is None:
                p.kill()
        print("serve output:\n" + (serve.stdout.read() or ""), file=sys.stderr)
        raise
    finally:
        for p in (send, serve):
            if p is not None and p.poll() is None:
                p.kill()


main()
