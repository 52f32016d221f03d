"""Outputs: the loop's records to its sinks (callback, recorder, UDP).

The 400 Hz records are written in place by the filter's batch kernel into a preallocated
buffer (:data:`gyrostar.loop.record.OUTPUT_DTYPE`; the kernel writes every field but the
latency); this stage stamps their latency (host time from the FIFO read to the emit, µs)
and hands the batch to every sink in one call.
"""

from __future__ import annotations

from . import record as R


class OutputStage:
    def __init__(self, sinks, lat_clock, capacity: int = 256):
        self.sinks = list(sinks)
        self.lat_clock = lat_clock
        self.buf = R.empty(capacity)
        self._latency = self.buf["latency_us"]    # a field view made once (making one costs µs)
        self._n = 0
        self.count = 0

    @property
    def last(self):
        """The newest record emitted (None before the first): a view into the buffer, valid
        until the next step (copy it to keep it)."""
        return self.buf[self._n - 1] if self._n else None

    def batch(self, n: int):
        """The first ``n`` records of the buffer, for the kernel to write."""
        return self.buf[:n]

    def emit(self, out, t_read: float, t_last: float) -> None:
        """Stamp latency (from ``t_read``, the FIFO read on the latency clock) and send."""
        n = len(out)
        lat = (self.lat_clock.now() - t_read) * 1e6
        if n == 1:
            self._latency[0] = lat
        else:
            self._latency[:n] = lat
        t_ns = int(t_last * 1e9)
        for sink in self.sinks:
            sink.put(out, t_ns)
        self._n = n
        self.count += n
