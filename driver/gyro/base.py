"""The gyro-device interface and the FIFO reading every FIFO gyro shares.

:class:`GyroDevice` is what the loop sees: ``probe()``, ``configure()``, ``self_test()``,
``start()``, ``read(out, event_time=None, event_clock=None)`` appending samples to a
:class:`~gyrostar.gyro.samples.GyroSamples`, plus ``odr_hz`` and ``range_dps``.

:class:`FifoGyro` implements ``read`` once for parts whose FIFO holds 6-byte XYZ int16
frames without timestamps (BMI088 gyro, L3GD20H): it asks the part for its FIFO level,
reads the frames in one burst, rebuilds frame indices and times
(:class:`~gyrostar.gyro.timebase.FrameTimebase`), and converts with the numba kernel.

Frame indices count from the FIFO start. Whenever frames may have been lost — a FIFO
overrun (also one that happened before the first read), a burst that failed after the
transfer began (the part already popped the frames it shifted out), a reconfiguration —
the index of the first frame read next is estimated from the time base (the newest frame
in the FIFO is the newest the part sampled), the jump is counted and flagged
(``FLAG_GAP``) and the row carries ``FLAG_TIME_EST``. A failed bus transaction raises
:class:`~gyrostar.errors.DeviceError`; rows already appended stay in ``out``.

Configuration is one register table (:mod:`.regtable`, after PX4's BMI088 driver):
``configure()`` applies and verifies it, and ``read()`` re-checks one entry every
``check_every`` reads, at most one per 25 ms (and the whole table when the FIFO stays
empty for longer than a watermark's worth of frames). A part that reset silently is counted
(``register_faults``, and ``GyroSamples.register_faults`` of the read that found it),
reconfigured and its FIFO restarted; the frames it did not keep are a flagged gap.
"""

from __future__ import annotations

import errno
import logging
import math
from abc import ABC, abstractmethod

import numpy as np

from ..clock import MONOTONIC
from ..errors import DeviceError
from .convert import FLAG_GAP, FLAG_SATURATED, FLAG_STUCK_AXIS, FLAG_TIME_EST, convert_frames
from .regtable import RegisterCheck, apply, verify
from .samples import GyroSamples
from .timebase import FrameTimebase

DPS = math.pi / 180.0
log = logging.getLogger(__name__)


class GyroDevice(ABC):
    """A rate gyro with a FIFO, seen from the loop."""

    odr_hz: float
    range_dps: float
    register_faults: int = 0   # configuration found lost in flight (and restored)

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
    def read(self, out: GyroSamples, event_time: float | None = None, event_clock=None) -> int:
        """Append every frame waiting in the FIFO (as many as fit) to ``out``; returns the count.
        ``event_time`` or ``event_clock``: the watermark interrupt edge (:meth:`FifoGyro.read`)."""


class FifoGyro(GyroDevice):
    """Shared FIFO reader. Subclasses provide the part-specific hooks below and build their
    register table in ``configure()`` (:meth:`_configure_table`)."""

    fifo_capacity: int = 32
    name = "gyro"
    check_every = 4   # FIFO reads between two in-flight checks (one table entry each), and ≥ 25 ms

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
        self.register_table: tuple = ()
        self.register_faults = 0
        self._check: RegisterCheck | None = None
        self._reconfigure_pending = False
        self._k_next: int | None = None
        self._resync = False
        self._last_event = -math.inf
        self._anchor_k = 0            # index of the first frame sampled after the last FIFO (re)start
        self._t_restart = -math.inf   # host time (s) of that (re)start
        self._drained = False         # frames were read since the (re)start
        self._t_data = -math.inf      # host time (s) of the last poll that found frames
        self._silence_checked = False
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
    def _configure_table(self, table) -> None:
        """Apply the register table and verify every entry; it becomes the in-flight check."""
        apply(self.regs, table)
        bad = verify(self.regs, table)
        if bad:
            more = f" (and {len(bad) - 1} more)" if len(bad) > 1 else ""
            raise DeviceError(f"{self.describe()}: configuration does not hold: {bad[0]}{more}")
        self.register_table = tuple(table)
        self._check = RegisterCheck(self.register_table, self.check_every)
        self._reconfigure_pending = False

    def describe(self) -> str:
        return f"{self.name} on {self.regs.describe()}"

    def start(self) -> None:
        if self.odr_hz <= 0:
            raise DeviceError(f"{self.describe()}: configure() before start()")
        self.timebase = FrameTimebase(1.0 / self.odr_hz)
        self._k_next = 0
        self._last_event = -math.inf
        self._prev[:] = 0
        self._restart_fifo(0)

    def _restart_fifo(self, anchor_k: int | None) -> None:
        """(Re)start the FIFO; the first frame sampled after now gets index ``anchor_k`` (None:
        the index the running time base gives it). The time base starts over from the
        assumption that it comes half a period later."""
        tb = self.timebase
        self._t_restart = self.clock.now()
        if anchor_k is None:
            anchor_k = max(tb.latest_index_at(self._t_restart) + 1, self._k_next)
        self._fifo_restart()
        tb.reset()
        tb.assume(anchor_k, self._t_restart + 0.5 * tb.nominal)
        self._anchor_k = anchor_k
        self._drained = False
        self._resync = False
        self._t_data = self._t_restart
        self._silence_checked = False

    def _register_fault(self, out: GyroSamples, what: str) -> None:
        self.register_faults += 1
        out.register_faults += 1
        log.warning("%s: %s: configuration lost (silent reset?); reconfiguring", self.describe(), what)
        self._reconfigure_pending = True
        self._reconfigure()

    def _reconfigure(self) -> None:
        """Apply the register table again and restart the FIFO; the frames the part did not
        keep meanwhile become a flagged gap. Retried on the next read if the bus fails."""
        self._configure_table(self.register_table)
        self._restart_fifo(None)

    def _check_config(self, out: GyroSamples, t_poll: float, empty: bool) -> None:
        """The in-flight register check, after the FIFO read (as PX4 does): one entry every
        ``check_every`` reads, the whole table once when the FIFO stays empty long after
        frames were due. A mismatch while the part still answers with its identity is a
        lost configuration; a bus that fails or returns garbage is not (the FIFO reads
        report it), so check errors only postpone the check."""
        if self._check is None:
            return
        try:
            if empty and not self._silence_checked and t_poll - self._t_data >= (self.watermark + 2) / self.odr_hz:
                self._silence_checked = True
                bad = next(iter(verify(self.regs, self.register_table)), None)
            elif self._check.due(t_poll):
                bad = self._check.check_next(self.regs)
            else:
                return
            if bad:
                self.probe()
                self._register_fault(out, bad)
        except DeviceError as exc:
            log.debug("%s: register check postponed: %s", self.describe(), exc)

    def read(self, out: GyroSamples, event_time: float | None = None, event_clock=None) -> int:
        """Append waiting frames to ``out``.

        ``event_time``: host time (s) of the most recent FIFO-watermark interrupt edge, if the
        caller timestamps the interrupt line; it anchors frame ``next + watermark − 1``.
        Without it the poll time bounds the newest frame's time. ``event_clock``, instead: the
        interrupt line's clock (``now()``: that edge's time, None or NaN before any), read
        here once per call right after the FIFO level — an edge that fires between the two
        belongs to the frames this read takes, and read before the level it would be taken
        for the next fill's (its frames stamped a whole fill early).
        """
        if self._k_next is None:
            raise DeviceError(f"{self.describe()}: start() before read()")
        try:
            if self._reconfigure_pending:
                self._reconfigure()
            tb = self.timebase
            t_poll = self.clock.now()
            count, lossy = self._fifo_level()
        finally:
            if event_clock is not None:       # once per call, whatever happened (a replay reads it back)
                edge = event_clock.now()
                event_time = edge if edge is not None and edge == edge else None
        if count > self.fifo_capacity:
            raise DeviceError(f"{self.describe()}: implausible FIFO level {count} "
                              f"(capacity {self.fifo_capacity}); bus data corrupt?")
        if count == 0:
            self._check_config(out, t_poll, empty=True)
            return 0
        n = min(count, out.room)
        if n == 0:
            return 0
        t_burst = self.clock.now()
        try:
            raw = self._fifo_burst(n)
        except DeviceError as exc:
            if getattr(exc, "errno", None) != errno.EREMOTEIO:
                self._resync = True  # the transfer began: the part may have popped frames it shifted out
            raise
        if len(raw) != 6 * n:
            self._resync = True
            raise DeviceError(f"{self.describe()}: FIFO burst returned {len(raw)} bytes, expected {6 * n}")
        if lossy or self._resync:
            if not self._drained and event_time is not None and self._t_restart < event_time \
                    and event_time > self._last_event:
                # the first watermark edge since the FIFO (re)start marks frame anchor + watermark − 1
                tb.add_event(self._anchor_k + self.watermark - 1, event_time)
                self._last_event = event_time
            # Frames may be gone: the FIFO held the newest ``count`` frames at the burst (a full
            # stream FIFO keeps overwriting until then) or at the poll (nothing was overwritten).
            t_ref = t_burst if lossy else t_poll
            first = max(tb.latest_index_at(t_ref) - count + 1, self._k_next)
            first_flags = FLAG_TIME_EST
        else:
            first = self._k_next if self._drained else max(self._anchor_k, self._k_next)
            first_flags = FLAG_TIME_EST if first != self._k_next else 0
        gap = first - self._k_next
        if gap:
            first_flags |= FLAG_GAP
        exact = (event_time is not None and not lossy and not self._resync and count >= self.watermark
                 and event_time > self._last_event)
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
        self._drained = True
        self._t_data = t_poll
        self._silence_checked = False
        if lossy and n == count and self._after_overrun():
            self._resync = True
        self._check_config(out, t_poll, empty=False)
        return n
