"""Outputs: the loop's records to its sinks (callback, recorder, UDP).

The 400 Hz records are written in place by the filter's batch kernel into a preallocated
buffer (:data:`gyrostar.loop.record.OUTPUT_DTYPE`); this stage stamps their latency (host
time from the FIFO read to the emit, µs) and hands the batch to every sink in one call.
"""

from __future__ import annotations

from . import record as R


class OutputStage:
    def __init__(self, sinks, lat_clock, capacity: int = 256):
        self.sinks = list(sinks)
        self.lat_clock = lat_clock
        self.buf = R.empty(capacity)
        self._blank = R.empty(1)[0]
        self.last = None
        self.count = 0

    def batch(self, n: int):
        """The first ``n`` records of the buffer, cleared, for the kernel to write."""
        out = self.buf[:n]
        out[:] = self._blank
        return out

    def emit(self, out, t_read: float, t_last: float) -> None:
        """Stamp latency (from ``t_read``, the FIFO read on the latency clock) and send."""
        out["latency_us"] = (self.lat_clock.now() - t_read) * 1e6
        t_ns = int(t_last * 1e9)
        for sink in self.sinks:
            sink.put(out, t_ns)
        self.last = out[-1].copy()
        self.count += len(out)
