#!/usr/bin/env python3
"""`fogbeam send` over CAN into `fogbeam serve` (issue 5): the lamp states of a scenario go out
as CAN frames through a DBC mapping, tunnelled as cannelloni over UDP (SocketCAN cannot be opened
on machines without AF_CAN; the decoding path is the same), and a candump -L log is written.

The service listens for cannelloni with the same mapping; its UDP input gets nothing (send's UDP
goes to a port nobody reads), so the light state in the frames can only have come over CAN. The
test requires frames with low beam only and with low + high beam (the scenario switches at 2 s
and back at 4 s) and a candump log that parses (one line per frame sent).

usage: send_can.py FOGBEAM CONFIG SCENARIO CAN_MAPPING READER_DIR
"""
import os
import signal
import subprocess
import sys
import tempfile
import time

sys.path.insert(0, sys.argv[5])
from fogbeam_reader import WriterGone  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from fogbeam_testlib import attach, free_port  # noqa: E402

FOGBEAM, CONFIG, SCENARIO, MAPPING = sys.argv[1:5]
LOW, HIGH = 0x2, 0x4


prefix = f"ctest-sendcan-{os.getpid()}-"
can_port, nobody = free_port(), free_port()
tmp = tempfile.mkdtemp(prefix="fogbeam-sendcan-")
log = os.path.join(tmp, "bus.log")
serve = subprocess.Popen([FOGBEAM, "serve", "--config", CONFIG, "--channel-prefix", prefix, "--duration", "600",
                          "--set", 'input.can.source="cannelloni"', "--set", f"input.can.cannelloni_port={can_port}",
                          "--set", f'input.can.mapping="{MAPPING}"'],
                         stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
send = None
try:
    # The first frame builds the tables: seconds here, over a minute in the -O0 + ASan build.
    reader = attach(prefix + "main", serve, timeout_s=300, first_frame=True)
    send = subprocess.Popen([FOGBEAM, "send", "--scenario", SCENARIO, "--to", f"127.0.0.1:{nobody}", "--rate", "30",
                             "--can-config", MAPPING, "--can-cannelloni", f"127.0.0.1:{can_port}", "--can-candump", log],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    seen, last = set(), None
    while send.poll() is None:
        try:
            got = reader.latest()
        except WriterGone:
            got = None
        if got is not None and got[0]["frame"] != last:
            last = got[0]["frame"]
            seen.add(got[0]["lights"] & (LOW | HIGH))
        time.sleep(0.002)
    out, _ = send.communicate(timeout=10)
    assert send.returncode == 0, out
    assert "CAN frames" in out, out
    assert LOW in seen and (LOW | HIGH) in seen, f"light states seen over CAN: {sorted(seen)}; send: {out}"
    lines = open(log).read().splitlines()
    assert len(lines) > 100 and all(l.startswith("(") and " can0 " in l and "#" in l for l in lines), lines[:3]
    reader.close()
    serve.send_signal(signal.SIGTERM)
    sout, _ = serve.communicate(timeout=30)
    assert serve.returncode == 0, sout
    print(f"send over CAN (cannelloni): light states seen in frames {sorted(seen)}; {len(lines)} candump lines; {out.strip()}")
finally:
    for p in (send, serve):
        if p is not None and p.poll() is None:
            p.kill()
