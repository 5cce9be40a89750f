#!/usr/bin/env python3
"""`fogbeam serve`'s frame loop under ThreadSanitizer (issue 6; run by scripts/tsan.sh with the
tsan build and TSAN_OPTIONS halt_on_error=1): the 60 Hz test cab, free-running, with every thread
the service has busy at once: the UDP receiver (`fogbeam send` at 60 Hz, traffic coming and
going), the CAN cannelloni receiver (the same send's lamp states over CAN), the status server
(a request every 100 ms), the heartbeat thread, the background fog/bending table builds and the
airlight workers, while a Python reader reads the frames. The service must exit 0 on SIGTERM with
no ThreadSanitizer report (a report makes it exit 66 at once with halt_on_error).

usage: tsan_serve.py FOGBEAM CONFIG SCENARIO CAN_MAPPING READER_DIR [SECONDS]
"""
import os
import signal
import subprocess
import sys
import time

FOGBEAM, CONFIG, SCENARIO, MAPPING, READER_DIR = sys.argv[1:6]
SECONDS = float(sys.argv[6]) if len(sys.argv) > 6 else 6.0
sys.path.insert(0, READER_DIR)
sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "serve"))
from fogbeam_reader import WriterGone  # noqa: E402
from fogbeam_testlib import attach, free_port, request_status  # noqa: E402

prefix = f"tsan-serve-{os.getpid()}-"
port, status_port, can_port = free_port(), free_port(), free_port()
serve = subprocess.Popen([FOGBEAM, "serve", "--config", CONFIG, "--channel-prefix", prefix, "--udp-port", str(port),
                          "--status-port", str(status_port), "--duration", str(SECONDS + 120),
                          "--set", 'input.can.source="cannelloni"', "--set", f"input.can.cannelloni_port={can_port}",
                          "--set", f'input.can.mapping="{MAPPING}"', "--set", "status.interval_s=0.5"],
                         stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
send = None
try:
    reader = attach(prefix + "main", serve, timeout_s=300, first_frame=True)
    send = subprocess.Popen([FOGBEAM, "send", "--scenario", SCENARIO, "--to", f"127.0.0.1:{port}", "--rate", "60",
                             "--loop", "--duration", str(SECONDS), "--can-config", MAPPING,
                             "--can-cannelloni", f"127.0.0.1:{can_port}"],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    frames, statuses, last = 0, 0, None
    next_status = time.monotonic()
    while send.poll() is None:
        try:
            got = reader.latest()
        except WriterGone:
            raise SystemExit("serve went away under TSan:\n" + serve.communicate(timeout=30)[0])
        if got is not None and got[0]["frame"] != last:
            last = got[0]["frame"]
            frames += 1
        if time.monotonic() >= next_status:
            request_status(status_port, timeout_s=5.0)
            statuses += 1
            next_status += 0.1
        time.sleep(0.002)
    send_out = send.stdout.read()
    assert send.returncode == 0, f"fogbeam send exited {send.returncode} (66: a ThreadSanitizer report):\n{send_out}"
    status = request_status(status_port, timeout_s=5.0)
    reader.close()
    serve.send_signal(signal.SIGTERM)
    out, _ = serve.communicate(timeout=120)
    assert "ThreadSanitizer" not in out, out
    assert serve.returncode == 0, f"serve exited {serve.returncode} (66: a ThreadSanitizer report):\n{out}"
    assert frames > 0 and status["udp"]["applied"] > 0, (frames, status)
    print(f"tsan: fogbeam serve for {SECONDS:.0f} s under ThreadSanitizer: {frames} frames read, {statuses} status "
          f"requests, UDP {status['udp']['applied']} applied, CAN lamps and traffic changing; no report")
finally:
    for p in (send, serve):
        if p is not None and p.poll() is None:
            p.kill()
