#!/usr/bin/env python3
"""End to end through `fogbeam serve` in lock-step mode (issue 5).

Starts the service on a small scene, drives it over UDP (docs/protocol.md) like a host would:
environment, lamp state, ego pose, then frame requests; reads every frame with the Python reader
(docs/shm.md) and checks the frame number, lights and input sequence numbers in its metadata.
Runs twice and requires identical pixels (lock-step runs are deterministic), then stops the
service with SIGTERM and requires a clean exit with the segment unlinked.

usage: serve_lockstep.py FOGBEAM_BINARY SERVICE_CONFIG READER_DIR
"""
import os
import signal
import socket
import struct
import subprocess
import sys
import time

sys.path.insert(0, sys.argv[3])
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from fogbeam_testlib import attach, free_port  # noqa: E402

FOGBEAM, CONFIG = sys.argv[1], sys.argv[2]
LOW_BEAM, HIGH_BEAM = 0x2, 0x4


def header(msg_type, payload, seq, t):
    return struct.pack("<IHHIId", 0x4D424746, 1, msg_type, len(payload), seq, t) + payload


def run_once(tag):
    prefix = f"ctest-lockstep-{os.getpid()}-{tag}-"
    channel = prefix + "main"
    port = free_port()
    proc = subprocess.Popen([FOGBEAM, "serve", "--config", CONFIG, "--channel-prefix", prefix, "--lock-step",
                             "--udp-port", str(port), "--duration", "60"],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        path = f"/dev/shm/fogbeam.{channel}"
        reader = attach(channel, proc, timeout_s=20)
        tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        seq = 0

        def send(msg_type, payload):
            nonlocal seq
            seq += 1
            tx.sendto(header(msg_type, payload, seq, 0.1 * seq), ("127.0.0.1", port))
            return seq

        env_seq = send(4, struct.pack("<fffBBBBfff", 60.0, 0.0, 1.0, 1, 0, 0, 0, 0.85, 10.0, 0.0))
        lamp_seq = send(2, struct.pack("<IfI", LOW_BEAM | HIGH_BEAM, 0.0, 0))
        # One oncoming car in the other lane, low beams on (a complete list, sent with every
        # pose as a host does: objects not updated for 1 s expire).
        car = (struct.pack("<HH", 1, 1) + struct.pack("<IHH", 7, 0, 0) +
               struct.pack("<dddfff", 40.0, 3.5, 0.0, 180.0, 0.0, 0.0) + struct.pack("<I", LOW_BEAM))
        frames = []
        for k in range(1, 5):
            send(3, car)
            ego_seq = send(1, struct.pack("<ddd fff f".replace(" ", ""), 5.0 * k, 0.0, 0.0, 2.0 * k, 0.0, 0.0, 12.0))
            time.sleep(0.05)  # the state is applied before the request (one socket, in order)
            send(5, struct.pack("<Q", 100 + k))
            deadline = time.monotonic() + 30
            while True:
                got = reader.latest()
                if got is not None and got[0]["frame"] == 100 + k:
                    break
                if time.monotonic() > deadline:
                    raise SystemExit(f"frame {100 + k} never published")
                time.sleep(0.005)
            meta, pixels = got
            assert meta["frame_request"] == 100 + k, meta
            assert meta["lights"] == LOW_BEAM | HIGH_BEAM, meta
            assert meta["ego_sequence"] == ego_seq, (meta, ego_seq)
            assert meta["lamp_sequence"] == lamp_seq and meta["environment_sequence"] == env_seq, meta
            assert abs(meta["yaw_deg"] - 2.0 * k) < 1e-6, meta
            assert meta["traffic_count"] == 1, meta
            frames.append(pixels.tobytes())
            print(f"  {tag}: frame {meta['frame']} total {meta['total_ms']:.1f} ms latency {meta['latency_ms']:.1f} ms")
        reader.close()
        proc.send_signal(signal.SIGTERM)
        out, _ = proc.communicate(timeout=20)
        assert proc.returncode == 0, f"serve exited {proc.returncode}: {out}"
        assert not os.path.exists(path), "segment not unlinked on SIGTERM"
        return frames
    except BaseException:
        if proc.poll() is None:
            proc.kill()
        print("serve output:\n" + proc.stdout.read(), file=sys.stderr)
        raise
    finally:
        if proc.poll() is None:
            proc.kill()


a = run_once("a")
b = run_once("b")
assert len(a) == len(b) == 4
for k, (x, y) in enumerate(zip(a, b)):
    assert x == y, f"frame {k}: lock-step runs differ"
print("serve lock-step: 4 frames per run, metadata as sent, two runs identical, clean SIGTERM exit")
