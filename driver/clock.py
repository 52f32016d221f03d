"""Clocks: the host's monotonic clock for hardware, a simulated clock for mocks.

Both expose the same two methods, in seconds:

* ``now() -> float`` — a monotonic time (s); never goes backwards.
* ``sleep(dt)`` — wait ``dt`` seconds (``dt <= 0`` returns at once).

Drivers take a clock and never call :mod:`time` directly, so a soft-reset wait of 30 ms
costs nothing under :class:`SimulatedClock` and tests run deterministically and faster
than real time.
"""

from __future__ import annotations

import threading
import time


class MonotonicClock:
    """The host monotonic clock (``time.monotonic``), seconds."""

    def now(self) -> float:
        return time.monotonic()

    def sleep(self, dt: float) -> None:
        if dt > 0:
            time.sleep(dt)


class SimulatedClock:
    """A deterministic clock that only moves when told to.

    ``sleep(dt)`` advances the time by ``dt`` at once; ``advance(dt)`` does the same for a
    test driving a scenario. Thread-safe: several threads may read and advance it.
    """

    def __init__(self, start: float = 0.0):
        self._t = float(start)
        self._lock = threading.Lock()

    def now(self) -> float:
        with self._lock:
            return self._t

    def sleep(self, dt: float) -> None:
        if dt > 0:
            self.advance(dt)

    def advance(self, dt: float) -> float:
        """Move the time forward by ``dt`` s (must be >= 0); returns the new time."""
        if dt < 0:
            raise ValueError(f"a simulated clock cannot go backwards (dt={dt} s)")
        with self._lock:
            self._t += dt
            return self._t

    def set(self, t: float) -> None:
        """Jump to absolute time ``t`` s (not before the current time)."""
        with self._lock:
            if t < self._t:
                raise ValueError(f"a simulated clock cannot go backwards ({t} < {self._t})")
            self._t = float(t)


MONOTONIC = MonotonicClock()
"""The shared host clock instance."""
