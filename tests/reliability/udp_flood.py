#!/usr/bin/env python3
"""UDP flood (issue 6; ctest label "reliability").

`fogbeam serve` (the 60 Hz test cab) is driven by `fogbeam send` at 60 Hz (4 valid datagrams per
state) while a second sender floods its port with about 1 500 datagrams per second, six times the
cab's rate: too short, bad magic, bad version, unknown type, wrong length, NaN in a pose, a value
out of range, and one valid message repeated (duplicates). Afterwards the service's status reply
must count every flood datagram under its reason and every valid datagram as applied (no valid
update lost), the last frame must carry the last ego message sent, and frames must have kept
coming (no gap over 1 s). Prints the frame rate and frame-time percentiles under the flood.

usage: udp_flood.py FOGBEAM CONFIG SCENARIO READER_DIR
"""
import json
import os
import re
import signal
import socket
import struct
import subprocess
import sys
import tempfile
import time

sys.path.insert(0, sys.argv[4])
sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "serve"))
from fogbeam_testlib import attach, free_port, request_status, start_serve  # noqa: E402

FOGBEAM, CONFIG, SCENARIO = sys.argv[1:4]
MAGIC = 0x4D424746


def header(msg_type, payload, seq, magic=MAGIC, version=1, length=None):
    return struct.pack("<IHHIId", magic, version, msg_type, len(payload) if length is None else length, seq, 1.0) + payload


ENV = struct.pack("<fffBBBBfff", 80.0, 0.0, 1.0, 1, 0, 0, 0, 0.85, 10.0, 0.0)  # the test cab's fog
EGO_NAN = struct.pack("<dddffff", float("nan"), 0.0, 0.0, 0.0, 0.0, 0.0, 10.0)
LAMP_BAD_BENDING = struct.pack("<IfI", 0x2, 90.0, 0)  # |bending| <= 45


def junk(kind, seq):
    if kind == "too_short":
        return b"\x46\x47\x42\x4d\x01\x00"
    if kind == "bad_magic":
        return header(4, ENV, seq, magic=0x12345678)
    if kind == "bad_version":
        return header(4, ENV, seq, version=9)
    if kind == "unknown_type":
        return header(77, ENV, seq)
    if kind == "length_mismatch":
        return header(4, ENV, seq, length=len(ENV) + 4)
    if kind == "non_finite":
        return header(1, EGO_NAN, seq)
    if kind == "out_of_range":
        return header(2, LAMP_BAD_BENDING, seq)
    raise ValueError(kind)


KINDS = ["too_short", "bad_magic", "bad_version", "unknown_type", "length_mismatch", "non_finite", "out_of_range"]

prefix = f"ctest-flood-{os.getpid()}-"
port, status_port = free_port(), free_port()
tmp = tempfile.mkdtemp(prefix="fogbeam-flood-")
sent_log = os.path.join(tmp, "sent.csv")
serve = start_serve(FOGBEAM, CONFIG, prefix, port, status_port)
send = None
try:
    reader = attach(prefix + "main", serve, first_frame=True)
    send = subprocess.Popen([FOGBEAM, "send", "--scenario", SCENARIO, "--to", f"127.0.0.1:{port}", "--rate", "60",
                             "--log", sent_log], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    flood = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    counts = {k: 0 for k in KINDS}
    counts["duplicate"] = 0
    seq = 1
    # One valid environment message (applied once), repeated below as duplicates.
    valid = header(4, ENV, 1_000_000)
    flood.sendto(valid, ("127.0.0.1", port))
    frames, last_t, max_gap = [], time.monotonic(), 0.0
    last_frame = None
    t0 = time.monotonic()
    next_batch = t0
    while send.poll() is None:
        now = time.monotonic()
        if now >= next_batch:  # 15 datagrams every 10 ms: 1 500 per second
            for i in range(15):
                kind = (KINDS + ["duplicate"])[(seq + i) % (len(KINDS) + 1)]
                flood.sendto(valid if kind == "duplicate" else junk(kind, seq + i), ("127.0.0.1", port))
                counts[kind] += 1
            seq += 15
            next_batch += 0.010
        got = reader.latest()
        if got is not None and got[0]["frame"] != last_frame:
            last_frame = got[0]["frame"]
            frames.append(got[0])
            max_gap = max(max_gap, now - last_t)
            last_t = now
        time.sleep(0.0005)
    flood_s = time.monotonic() - t0
    send_out, _ = send.communicate(timeout=30)
    assert send.returncode == 0, send_out
    valid_sent = int(re.search(r"(\d+) datagrams to", send_out).group(1))
    time.sleep(0.3)
    status = request_status(status_port)
    udp = status["udp"]
    flood_total = sum(counts.values()) + 1
    assert udp["datagrams"] == valid_sent + flood_total, (udp, valid_sent, flood_total)
    assert udp["applied"] == valid_sent + 1, f"valid updates lost: applied {udp['applied']} of {valid_sent} + 1"
    for kind, n in counts.items():
        assert udp["dropped"].get(kind, 0) == n, f"{kind}: {udp['dropped'].get(kind, 0)} counted, {n} sent: {udp}"
    last_ego = int(open(sent_log).read().strip().splitlines()[-1].split(",")[2])
    final = reader.latest()[0]
    assert final["ego_sequence"] == last_ego, (final["ego_sequence"], last_ego)
    assert max_gap < 1.0, f"frames stopped for {max_gap:.2f} s under the flood"
    reader.close()
    serve.send_signal(signal.SIGTERM)
    out, _ = serve.communicate(timeout=30)
    assert serve.returncode == 0, out
    total = sorted(m["total_ms"] for m in frames)
    span = (frames[-1]["publish_ns"] - frames[0]["publish_ns"]) / 1e9
    published = frames[-1]["frame"] - frames[0]["frame"] + 1
    print(f"udp flood: {flood_total} flood datagrams in {flood_s:.1f} s ({flood_total / flood_s:.0f}/s) beside "
          f"{valid_sent} valid ones ({valid_sent / flood_s:.0f}/s): all {valid_sent} valid applied, every flood datagram "
          f"counted under its reason {json.dumps(udp['dropped'])}")
    print(f"  frames under the flood: {published} in {span:.2f} s ({published / span:.1f} fps), longest gap "
          f"{max_gap * 1000:.0f} ms, frame time p50 {total[len(total) // 2]:.2f} ms p95 "
          f"{total[int(0.95 * len(total))]:.2f} ms; last frame carries the last ego message sent")
finally:
    for p in (send, serve):
        if p is not None and p.poll() is None:
            p.kill()
