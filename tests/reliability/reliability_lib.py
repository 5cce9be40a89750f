"""Helpers of the reliability tests (issue 6) beside tests/serve/fogbeam_testlib.py: a frame
auditor that reads every slot of a channel and checks each copy for tearing, and the resident
memory of a process."""
import hashlib
import math
import struct
import time

from fogbeam_reader import FogbeamReader


class FrameAuditor:
    """Reads every slot of a channel (docs/shm.md) under the seqlock, so that a poll every few
    milliseconds sees every frame a 60 Hz writer publishes (three slots = 50 ms of frames), and
    checks every accepted copy for tearing independently of the seqlock: each frame is read
    several times while it stays in its slot (polls are ~10 times faster than the frame rate),
    and every copy of frame N must equal, byte for byte (metadata and pixels), the first copy
    of frame N. A copy that mixed two frames would differ. It also checks that frame N sits in
    slot (N - 1) mod slots (the writer fills the slot after the last one written).

    Missed frames: the service numbers its frames 1, 2, 3, … without gaps, so a frame number the
    auditor never saw was published and overwritten before a poll read it. That takes the writer
    `slots` periods after the frame; with polls `stall_s` (2 periods) apart or closer, a paced
    writer cannot do it. A frame missed across a poll interval longer than `stall_s` was lost by
    the reader (this Python process descheduled on a loaded machine): counted in
    `missed_reader_stalled`, but only as many as a paced writer can have published and overwritten
    in that interval (ceil(interval / period) + 2 frames published, one for the jitter of the
    publish times about their deadlines, the last `slots` of them still
    in the ring); any beyond that, and any missed across a shorter interval, mean the writer burst
    or a slot went unread: counted in `missed_unexplained`, which the tests require to be 0. The
    time the reader spent in such long intervals is summed in `stalled_s`."""

    def __init__(self, reader: FogbeamReader, period_s=1.0 / 60.0):
        self.r = reader
        self.period_s = period_s
        self.stall_s = 2.0 * period_s
        self.stalled_s = 0.0             # total of the poll intervals longer than stall_s
        self.last_poll = None
        self.max_frame = None
        self.missed_reader_stalled = 0   # frames lost while the reader did not poll for > stall_s
        self.missed_unexplained = 0      # frames lost between polls closer than stall_s
        self.longest_poll_gap_s = 0.0
        self.digests = {}       # frame -> sha1 of its first accepted copy (the last 64 frames kept)
        self.frames = {}        # frame -> metadata of its first accepted copy (caller may prune)
        self.copies = 0         # accepted copies
        self.compared = 0       # copies compared with an earlier copy of the same frame
        self.torn = 0           # copies that differed from the first copy of their frame
        self.retries = 0        # copies refused by the seqlock (written during the copy)
        self.misplaced = 0      # frames found in a slot other than (frame - 1) mod slots

    def poll(self):
        """Reads each slot once; returns the frame numbers seen for the first time."""
        r, m = self.r, self.r._m
        now = time.monotonic()
        interval = 0.0 if self.last_poll is None else now - self.last_poll
        self.last_poll = now
        self.longest_poll_gap_s = max(self.longest_poll_gap_s, interval)
        if interval > self.stall_s:
            self.stalled_s += interval
        # Frames a paced writer can publish in `interval` and overwrite before this poll.
        explainable = max(0, math.ceil(interval / self.period_s) + 2 - self.r.slots) if interval > self.stall_s else 0
        new = []
        for slot in range(r.slots):
            base = r.first_slot + slot * r.stride
            s1 = struct.unpack_from("<Q", m, base)[0]
            if s1 == 0 or s1 % 2:  # never written, or being written
                continue
            raw = m[base:base + r.pixels_offset + r.pixels_bytes]
            if struct.unpack_from("<Q", m, base)[0] != s1:
                self.retries += 1
                continue
            meta = FogbeamReader._meta(raw)
            frame = meta["frame"]
            self.copies += 1
            digest = hashlib.sha1(raw[8:]).digest()  # all but the seqlock counter
            if frame in self.digests:
                self.compared += 1
                if self.digests[frame] != digest:
                    self.torn += 1
                continue
            self.digests[frame] = digest
            if len(self.digests) > 64:
                del self.digests[min(self.digests)]
            if (frame - 1) % r.slots != slot:
                self.misplaced += 1
            self.frames[frame] = meta
            new.append(frame)
        for frame in sorted(new):
            if self.max_frame is not None and frame > self.max_frame + 1:
                lost = frame - self.max_frame - 1
                stalled = min(lost, explainable)
                explainable -= stalled
                self.missed_reader_stalled += stalled
                self.missed_unexplained += lost - stalled
            if self.max_frame is None or frame > self.max_frame:
                self.max_frame = frame
        return new

    def summary(self):
        return (f"{self.copies} copies accepted, {self.compared} compared with an earlier copy of the same frame, "
                f"{self.torn} torn, {self.retries} refused by the seqlock, {self.misplaced} in the wrong slot; frames "
                f"missed: {self.missed_unexplained} unexplained, {self.missed_reader_stalled} while this reader was "
                f"descheduled (longest poll gap {self.longest_poll_gap_s * 1000:.0f} ms, {self.stalled_s * 1000:.0f} ms in "
                f"gaps over {self.stall_s * 1000:.0f} ms)")


def rss_kib(pid):
    """Resident memory of a process (VmRSS in /proc/<pid>/status), KiB."""
    with open(f"/proc/{pid}/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1])
    raise RuntimeError(f"no VmRSS for pid {pid}")


def gaps(frame_numbers):
    """Frame numbers missing between the smallest and the largest of those given."""
    s = sorted(frame_numbers)
    return sum(b - a - 1 for a, b in zip(s, s[1:]) if b > a + 1)
