"""Helpers shared by the end-to-end tests of `fogbeam serve` (tests/serve, tests/timing):
loopback ports, attaching the Python host reader to a channel a starting service creates."""
import json
import socket
import subprocess
import time

from fogbeam_reader import FogbeamReader, WriterGone


def free_port():
    """A UDP port free on 127.0.0.1 now (the service binds it a moment later)."""
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    return port


def attach(channel, proc, timeout_s=60.0, first_frame=False):
    """A reader on /fogbeam.<channel>, retrying while the service starts (the segment appears
    before its header is written); with first_frame, also waits for a published frame (the
    first one builds the tables). SystemExit with the service's output if it exits or times out."""
    end = time.monotonic() + timeout_s
    while True:
        try:
            reader = FogbeamReader(channel)
            if not first_frame or reader.latest() is not None:
                return reader
            reader.close()
        except (FileNotFoundError, ValueError, WriterGone):
            pass
        if proc.poll() is not None or time.monotonic() > end:
            raise SystemExit(f"serve did not publish on /fogbeam.{channel}: "
                             + (proc.stdout.read() if proc.poll() is not None else "(timed out)"))
        time.sleep(0.02)


def start_serve(fogbeam, config, prefix, udp_port, status_port, duration_s=120):
    """`fogbeam serve` on a test cab: its channels prefixed, UDP and status on the given ports."""
    return subprocess.Popen([fogbeam, "serve", "--config", config, "--channel-prefix", prefix, "--udp-port", str(udp_port),
                             "--status-port", str(status_port), "--duration", str(duration_s)],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)


def request_status(port, timeout_s=2.0):
    """The service's status reply (docs/service.md) as a dict."""
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.settimeout(timeout_s)
    s.sendto(b"status", ("127.0.0.1", port))
    data, _ = s.recvfrom(65536)
    s.close()
    return json.loads(data)
