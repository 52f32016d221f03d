"""The gyro-device interface and the FIFO reading every FIFO gyro shares.

:class:`GyroDevice` is what the loop sees: ``probe()``, ``configure()``, ``self_test()``,
``start()``, ``read(out, event_time=None)`` appending samples to a
:class:`~gyrostar.gyro.samples.GyroSamples`, plus ``odr_hz`` and ``range_dps``.

:class:`FifoGyro` implements ``read`` once for parts whose FIFO holds 6-byte XYZ int16
frames without timestamps (BMI088 gyro, L3GD20H): it asks the part for its FIFO level,
reads the frames in one burst, rebuilds frame indices (a jump after a FIFO overrun is
counted and flagged) and times (:class:`~gyrostar.gyro.timebase.FrameTimebase`), and converts
with the numba kernel. A failed bus transaction raises
:class:`~gyrostar.errors.DeviceError` before any state changes: frames not yet read stay in
the device FIFO and rows already appended stay in ``out``.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod

import numpy as np

from ..clock import MONOTONIC
from ..errors import DeviceError
from .convert import FLAG_GAP, FLAG_SATURATED, FLAG_STUCK_AXIS, FLAG_TIME_EST, convert_frames
from .samples import GyroSamples
from .timebase import FrameTimebase

DPS = math.pi / 180.0


class GyroDevice(ABC):
    """A rate gyro with a FIFO, seen from the loop."""

    odr_hz: float
    range_dps: float

    @abstractmethod
    def probe(self) -> None:
        """Check the part answers with its identity; :class:`DeviceError` otherwise."""

    @abstractmethod
    def configure(self, odr_hz: float, range_dps: float, watermark: int) -> None:
        """Reset the part and set rate, range and FIFO watermark (frames); verify by read-back."""

    @abstractmethod
    def self_test(self) -> bool:
        """Run the part's built-in self test; True when it passes. Leaves the part reset."""

    @abstractmethod
    def start(self) -> None:
        """Start the FIFO (stream mode); sample indices count from here."""

    @abstractmethod
    def read(self, out: GyroSamples, event_time: float | None = None) -> int:
        """Append every frame waiting in the FIFO (as many as fit) to ``out``; returns the count."""


class FifoGyro(GyroDevice):
    """Shared FIFO reader. Subclasses provide the part-specific hooks below."""

    fifo_capacity: int = 32
    name = "gyro"

    def __init__(self, regs, clock=MONOTONIC, mounting=None):
        self.regs = regs
        self.clock = clock
        self.mounting = np.eye(3) if mounting is None else np.ascontiguousarray(mounting, np.float64)
        if self.mounting.shape != (3, 3):
            raise ValueError("mounting must be a 3×3 rotation sensor→body")
        self.odr_hz = 0.0
        self.range_dps = 0.0
        self.watermark = 0
        self.scale = 0.0  # rad/s per LSB
        self.timebase: FrameTimebase | None = None
        self._k_next: int | None = None
        self._resync = False
        self._last_event = -math.inf
        self._prev = np.zeros(8, np.int32)   # last frame, valid, per-axis unchanged-frame runs

    # --- part-specific hooks -------------------------------------------------------------
    @abstractmethod
    def _fifo_level(self) -> tuple[int, bool]:
        """``(frames waiting, lossy)``; lossy when frames may have been overwritten."""

    @abstractmethod
    def _fifo_burst(self, n: int) -> bytes:
        """Read ``n`` frames (6·n bytes) in one bus transaction."""

    @abstractmethod
    def _after_overrun(self) -> bool:
        """Clear an overrun condition; True if that discarded frames (indices must resync)."""

    @abstractmethod
    def _fifo_restart(self) -> None:
        """Empty the FIFO and (re)start it in stream mode."""

    # --- shared ----------------------------------------------------------------------------
    def _write_verified(self, name: str, reg: int, value: int, mask: int = 0xFF) -> None:
        """Write a configuration register and check it reads back (under ``mask``)."""
        self.regs.write(reg, bytes([value]))
        back = self.regs.read(reg, 1)[0]
        if back & mask != value & mask:
            raise DeviceError(f"{self.describe()}: {name} (0x{reg:02X}) reads back 0x{back:02X} after "
                              f"writing 0x{value:02X}")

    def describe(self) -> str:
        return f"{self.name} on {self.regs.describe()}"

    def start(self) -> None:
        if self.odr_hz <= 0:
            raise DeviceError(f"{self.describe()}: configure() before start()")
        self.timebase = FrameTimebase(1.0 / self.odr_hz)
        self._fifo_restart()
        self._t_start = self.clock.now()
        self._k_next = 0
        self._resync = False
        self._last_event = -math.inf
        self._prev[:] = 0

    def read(self, out: GyroSamples, event_time: float | None = None) -> int:
        """Append waiting frames to ``out``.

        ``event_time``: host time (s) of the most recent FIFO-watermark interrupt edge, if the
        caller timestamps the interrupt line; it anchors frame ``next + watermark − 1``.
        Without it the poll time bounds the newest frame's time.
        """
        if self._k_next is None:
            raise DeviceError(f"{self.describe()}: start() before read()")
        tb = self.timebase
        t_poll = self.clock.now()
        count, lossy = self._fifo_level()
        if count > self.fifo_capacity:
            raise DeviceError(f"{self.describe()}: implausible FIFO level {count} "
                              f"(capacity {self.fifo_capacity}); bus data corrupt?")
        if count == 0:
            return 0
        n = min(count, out.room)
        if n == 0:
            return 0
        t_burst = self.clock.now()
        raw = self._fifo_burst(n)  # DeviceError here: nothing consumed, nothing changed
        first = self._k_next
        first_flags = 0
        if (lossy or self._resync) and tb.ready:
            # Frames may have been overwritten: the FIFO held the newest ``count`` frames when
            # the burst started (a full stream FIFO keeps overwriting until then).
            t_ref = t_burst if lossy else t_poll
            first = max(tb.latest_index_at(t_ref) - count + 1, self._k_next)
            first_flags = FLAG_TIME_EST
        gap = first - self._k_next
        if gap:
            first_flags |= FLAG_GAP
        exact = (event_time is not None and not lossy and not self._resync and count >= self.watermark
                 and event_time > self._last_event)
        if len(raw) != 6 * n:
            raise DeviceError(f"{self.describe()}: FIFO burst returned {len(raw)} bytes, expected {6 * n}")
        if exact:
            tb.add_event(first + self.watermark - 1, event_time)
            self._last_event = event_time
        elif not (first_flags & FLAG_TIME_EST):  # an index taken from the time base adds no information
            tb.add_bound(first + count - 1, t_poll)
        buf = np.frombuffer(raw, np.uint8)
        convert_frames(buf, n, self.scale, self.mounting, tb.t_ref, tb.period, tb.k_ref, first, first_flags,
                       self._prev, out.t, out.index, out.rate, out.flags, out.n)
        new_flags = out.flags[out.n:out.n + n]
        out.saturated += int(np.count_nonzero(new_flags & FLAG_SATURATED))
        out.stuck_axis += int(np.count_nonzero(new_flags & FLAG_STUCK_AXIS))
        out.n += n
        if gap:
            out.gap_frames += gap
            out.gaps += 1
        self._k_next = first + n
        self._resync = False
        if lossy and n == count and self._after_overrun():
            self._resync = True
        return n
