#!/usr/bin/env python3
"""fogbeam — read frames from a fogbeam shared-memory channel (docs/shm.md) in Python.

Standard library plus numpy. For scripting and tests:

    from fogbeam_reader import FogbeamReader
    r = FogbeamReader("main")
    meta, pixels = r.latest()      # pixels: numpy array (height, width, 4), row 0 at the top
    r.close()

Formats: 1 RGBA8 sRGB -> uint8; 2 RGBA16F linear and 3 RGBA16F overlay -> float16;
4 host depth (f32 distance) -> float32 (height, width). Command line:

    fogbeam_reader.py CHANNEL [--frames N] [--timeout S]   prints one JSON line per new frame

The host's side of the cab loop (docs/shm.md, "Host depth input"; docs/service.md, "Host depth"):

    from fogbeam_reader import FogbeamDepthWriter
    w = FogbeamDepthWriter("host-depth", 640, 360)
    w.publish(distances, frame=1, sim_time_s=0.0, position_m=(0, 0.37, 1.2), fov_x_deg=60.0)
    w.close()
"""
import argparse
import json
import mmap
import os
import struct
import sys
import time

import numpy as np

MAGIC = 0x53424746
VERSION = 2
HEADER_SIZE = 256
FORMATS = {1: (np.uint8, 4), 2: (np.float16, 4), 3: (np.float16, 4), 4: (np.float32, 1)}
WRITER_CLOSED = 2


class WriterGone(Exception):
    """The writer closed the channel, stopped its heartbeat, or died: attach again."""


class FogbeamReader:
    def __init__(self, channel):
        if not channel or len(channel) > 48 or not all(c.isalnum() or c in "_.-" for c in channel):
            raise ValueError(f"channel '{channel}': expected 1-48 characters from [A-Za-z0-9_.-]")
        path = f"/dev/shm/fogbeam.{channel}"
        fd = os.open(path, os.O_RDONLY)
        try:
            size = os.fstat(fd).st_size
            if size < HEADER_SIZE:
                raise ValueError(f"{path}: {size} bytes, smaller than the header")
            self._m = mmap.mmap(fd, size, prot=mmap.PROT_READ)
        finally:
            os.close(fd)
        m = self._m
        magic, version, _, self.slots, self.format, self.width, self.height, bpp, has_dist = struct.unpack_from(
            "<IHHIIIIII", m, 0)
        if magic != MAGIC:
            raise ValueError(f"{path}: not a fogbeam channel")
        if version != VERSION:
            raise ValueError(f"{path}: layout version {version}, this reader knows {VERSION}")
        (self.first_slot, self.stride, self.pixels_offset, self.pixels_bytes, self.distance_offset, declared,
         self.generation) = struct.unpack_from("<QQQQQQQ", m, 32)
        if declared != size or self.first_slot + self.stride * self.slots > size or self.format not in FORMATS:
            raise ValueError(f"{path}: inconsistent header")
        dtype, channels = FORMATS[self.format]
        if self.pixels_bytes != self.width * self.height * channels * np.dtype(dtype).itemsize:
            raise ValueError(f"{path}: pixel size does not match the format")
        self.path = path
        self._dtype, self._channels = dtype, channels

    def close(self):
        self._m.close()

    def writer_alive(self):
        """False when the writer's pid (header offset 88) no longer exists: a killed writer is seen
        at once, not after the heartbeat timeout. A pid of another user's process (EPERM) is alive."""
        pid = struct.unpack_from("<I", self._m, 88)[0]
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return False
        except PermissionError:
            pass
        return True

    def _u64(self, off):
        return struct.unpack_from("<Q", self._m, off)[0]

    def latest(self, heartbeat_timeout_s=2.0, attempts=8):
        """(meta dict, pixels) of the newest whole frame; None when none is published yet.
        Raises WriterGone; returns None after `attempts` overlapping writes (try again)."""
        m = self._m
        state = struct.unpack_from("<I", m, 92)[0]
        beat = self._u64(96)
        if state == WRITER_CLOSED or (time.clock_gettime_ns(time.CLOCK_MONOTONIC) - beat) * 1e-9 > heartbeat_timeout_s:
            raise WriterGone(self.path)
        if not self.writer_alive():  # docs/shm.md: a writer whose pid is gone is gone at once
            raise WriterGone(self.path)
        for _ in range(attempts):
            latest = self._u64(104)
            if latest == 0:
                return None
            slot = latest & 0xFF
            base = self.first_slot + slot * self.stride
            s1 = self._u64(base)
            if s1 % 2:
                continue
            raw = m[base:base + self.pixels_offset + self.pixels_bytes]  # one copy, then checked
            s2 = self._u64(base)
            if s1 != s2:
                continue
            meta = self._meta(raw)
            pixels = np.frombuffer(raw, dtype=self._dtype, offset=self.pixels_offset,
                                   count=self.width * self.height * self._channels)
            shape = (self.height, self.width) if self._channels == 1 else (self.height, self.width, self._channels)
            return meta, pixels.reshape(shape).copy()
        return None

    @staticmethod
    def _meta(raw):
        (frame, sim_time, x, y, z, yaw, pitch, roll, lights, ego_seq, lamp_seq, env_seq, traffic, surface_ms,
         airlight_ms, composite_ms, total_ms, latency_ms, publish_ns, frame_request, fov_x, fov_y,
         left, right, up, down, host_frame) = struct.unpack_from(
            "<Qddddfff" "IIIII" "ddddd" "QQ" "ff" "ffff" "Q", raw, 8)  # docs/shm.md, slot metadata from offset 8
        return {"frame": frame, "sim_time_s": sim_time, "position_m": [x, y, z], "yaw_deg": yaw,
                "pitch_deg": pitch, "roll_deg": roll, "lights": lights, "ego_sequence": ego_seq,
                "lamp_sequence": lamp_seq, "environment_sequence": env_seq, "traffic_count": traffic,
                "surface_ms": surface_ms, "airlight_ms": airlight_ms, "composite_ms": composite_ms,
                "total_ms": total_ms, "latency_ms": latency_ms, "publish_ns": publish_ns,
                "frame_request": frame_request, "fov_x_deg": fov_x, "fov_y_deg": fov_y,
                "frustum_deg": [left, right, up, down], "host_frame": host_frame}


class FogbeamDepthWriter:
    """The host's depth channel (format 4) from Python: what fogbeam_depth_create/publish do in C.

    Writes the layout of docs/shm.md with plain stores into the mapping, which is a correct
    seqlock on x86-64 only (stores are not reordered with stores there; Python has no fences):
    on other machines, use the C SDK. The heartbeat is stamped at each publish and by
    heartbeat(): publish or beat at least once a second, or fogbeam counts the host gone (2 s).
    """

    SLOTS = 3

    def __init__(self, channel, width, height):
        if not channel or len(channel) > 48 or not all(c.isalnum() or c in "_.-" for c in channel):
            raise ValueError(f"channel '{channel}': expected 1-48 characters from [A-Za-z0-9_.-]")
        if not (1 <= width <= 16384 and 1 <= height <= 16384):
            raise ValueError(f"size {width}x{height}: expected 1-16384 pixels a side")
        self.width, self.height = width, height
        self.path = f"/dev/shm/fogbeam.{channel}"
        pixels = width * height * 4
        self._stride = HEADER_SIZE + (pixels + 63) // 64 * 64  # slot metadata 256 B + pixels, 64-byte multiple
        size = HEADER_SIZE + self.SLOTS * self._stride
        fd = os.open(self.path, os.O_CREAT | os.O_EXCL | os.O_RDWR, 0o600)
        try:
            os.ftruncate(fd, size)
            self._m = mmap.mmap(fd, size)
        finally:
            os.close(fd)
        m = self._m
        self.generation = struct.unpack("<Q", os.urandom(8))[0] | 1
        struct.pack_into("<HHIIIIII", m, 4, VERSION, HEADER_SIZE, self.SLOTS, 4, width, height, 4, 0)
        struct.pack_into("<QQQQQQQ", m, 32, HEADER_SIZE, self._stride, HEADER_SIZE, pixels, 0, size, self.generation)
        struct.pack_into("<II", m, 88, os.getpid(), 1)  # pid, state running
        self.heartbeat()
        name = channel.encode()[:63]
        m[128:128 + len(name)] = name
        struct.pack_into("<I", m, 0, MAGIC)  # the magic last: a reader that sees it sees a whole header
        self._next = 0

    def heartbeat(self):
        struct.pack_into("<Q", self._m, 96, time.clock_gettime_ns(time.CLOCK_MONOTONIC))

    def publish(self, distance_m, frame, sim_time_s=0.0, position_m=(0.0, 0.0, 0.0), yaw_deg=0.0, pitch_deg=0.0,
                roll_deg=0.0, fov_x_deg=60.0, fov_y_deg=0.0, frustum_deg=(0.0, 0.0, 0.0, 0.0)):
        """One view: distance_m (height x width float32, metres along each pixel's ray, inf = sky,
        row 0 at the top) and the camera (docs/shm.md). frame numbers start at 1."""
        if frame < 1:
            raise ValueError("frame numbers start at 1 (a latest word of 0 means no frame yet)")
        d = np.ascontiguousarray(distance_m, dtype=np.float32)
        if d.shape != (self.height, self.width):
            raise ValueError(f"distance_m of shape {d.shape}, expected ({self.height}, {self.width})")
        m = self._m
        slot = self._next
        self._next = (self._next + 1) % self.SLOTS
        base = HEADER_SIZE + slot * self._stride
        seq = struct.unpack_from("<Q", m, base)[0]
        struct.pack_into("<Q", m, base, seq + 1)  # odd: being written
        now = time.clock_gettime_ns(time.CLOCK_MONOTONIC)
        struct.pack_into("<Qddddfff", m, base + 8, frame, sim_time_s, *position_m, yaw_deg, pitch_deg, roll_deg)
        struct.pack_into("<Q", m, base + 120, now)
        struct.pack_into("<ff", m, base + 136, fov_x_deg, fov_y_deg)
        struct.pack_into("<ffff", m, base + 144, *frustum_deg)
        m[base + HEADER_SIZE:base + HEADER_SIZE + d.nbytes] = d.tobytes()
        struct.pack_into("<Q", m, base, seq + 2)  # even: whole
        struct.pack_into("<Q", m, 104, (frame << 8) | slot)
        self.heartbeat()

    def close(self):
        """Marks the channel closed and removes it (as the C writer does on a clean exit)."""
        struct.pack_into("<I", self._m, 92, WRITER_CLOSED)
        self._m.close()
        try:
            os.unlink(self.path)
        except FileNotFoundError:
            pass


def main(argv):
    ap = argparse.ArgumentParser(description="Print the frames of a fogbeam channel as JSON lines.")
    ap.add_argument("channel")
    ap.add_argument("--frames", type=int, default=1, help="new frames to print before exiting (default 1)")
    ap.add_argument("--timeout", type=float, default=5.0, help="seconds to wait in all (default 5)")
    a = ap.parse_args(argv)
    end = time.monotonic() + a.timeout
    reader = None
    while reader is None:
        try:
            reader = FogbeamReader(a.channel)
        except (FileNotFoundError, ValueError):  # not there yet, or its header not yet written
            if time.monotonic() > end:
                print(f"fogbeam_reader: no channel '{a.channel}'", file=sys.stderr)
                return 1
            time.sleep(0.01)
    seen, last = 0, None
    while seen < a.frames and time.monotonic() < end:
        got = reader.latest()
        if got is None or got[0]["frame"] == last:
            time.sleep(0.001)
            continue
        meta, pixels = got
        last = meta["frame"]
        meta["shape"] = list(pixels.shape)
        meta["dtype"] = str(pixels.dtype)
        meta["mean"] = [float(v) for v in np.asarray(pixels, dtype=np.float64).reshape(-1, pixels.shape[-1]).mean(axis=0)]
        print(json.dumps(meta), flush=True)
        seen += 1
    reader.close()
    return 0 if seen >= a.frames else 1


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
