"""Streamed frames: FRAME parts pushed by the head, assembled into whole frames.

A streaming head (START_STREAM) pushes every frame it reads as one or more FRAME messages
carrying the START_STREAM's seq; each part holds windows ``start .. start + count`` of
``total``. :class:`FrameAssembler` collects the parts of each frame number and hands out
complete :class:`StreamFrame` objects in frame order; a frame whose parts stop coming (a
part lost to corruption) is given up once a later frame completes, and counted.
"""

from __future__ import annotations

import dataclasses
from collections import deque


@dataclasses.dataclass(frozen=True)
class StreamFrame:
    """One streamed exposure: head times (MCU µs), host times (monotonic s), its windows and
    the head's stream counters at that frame."""

    frame: int
    set_frame: int            # frame named by the SET_WINDOWS whose windows were read (0: none)
    t_start_us: int
    t_end_us: int
    exposure_us: int
    late_sets: int
    dropped: int
    backpressure: int
    n_pixels: int
    windows: list             # protocol.payloads.WindowPixels, window order of the set
    t_mid_host: float         # exposure mid-time, host monotonic s (nan before time sync)
    t_rx: float               # host arrival time of the frame's last part (s)
    wire_bytes: int           # bytes of its FRAME messages on the link (COBS + delimiter)


class FrameAssembler:
    """Parts → frames. ``add(fields, t_rx, n_bytes, to_host)`` returns a finished
    :class:`StreamFrame` or None; ``to_host(mcu_us)`` maps MCU µs to host s."""

    def __init__(self, max_open: int = 4):
        self.max_open = max_open
        self._open: dict[int, dict] = {}
        self.given_up = 0         # frames with parts missing
        self.bad_parts = 0        # parts that disagree with their frame's first part
        self.last_frame = 0

    def add(self, f: dict, t_rx: float, n_bytes: int, to_host) -> StreamFrame | None:
        k = f["frame"]
        if k <= self.last_frame:
            self.bad_parts += 1           # a part of a frame already given out or given up
            return None
        st = self._open.get(k)
        if st is None:
            st = self._open[k] = {"f": f, "windows": [], "next": 0, "bytes": 0}
        if f["start"] != st["next"] or f["total"] != st["f"]["total"]:
            self.bad_parts += 1
            del self._open[k]
            self.given_up += 1
            return None
        st["windows"].extend(f["windows"])
        st["next"] += f["count"]
        st["bytes"] += n_bytes
        if st["next"] < f["total"]:
            if len(self._open) > self.max_open:
                self._drop_before(k)
            return None
        del self._open[k]
        self._drop_before(k)
        self.last_frame = k
        h = st["f"]
        mid = 0.5 * (h["t_start_us"] + h["t_end_us"])
        return StreamFrame(k, h["set_frame"], h["t_start_us"], h["t_end_us"], h["exposure_us"], h["late_sets"],
                           h["dropped"], h["backpressure"], h["n_pixels"], st["windows"], to_host(mid), t_rx,
                           st["bytes"])

    def _drop_before(self, k: int) -> None:
        for old in [j for j in self._open if j < k]:
            del self._open[old]
            self.given_up += 1


class FrameQueue:
    """Complete frames waiting for the caller (bounded: the oldest is dropped and counted)."""

    def __init__(self, depth: int = 8):
        self._q: deque = deque()
        self.depth = depth
        self.overflow = 0

    def put(self, fr: StreamFrame) -> None:
        if len(self._q) >= self.depth:
            self._q.popleft()
            self.overflow += 1
        self._q.append(fr)

    def get(self) -> StreamFrame | None:
        return self._q.popleft() if self._q else None

    def __len__(self) -> int:
        return len(self._q)
