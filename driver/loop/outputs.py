"""Outputs: the loop's records to its sinks (callback, UDP, space packets, recorder).

The 400 Hz records are written in place by the filter's batch kernel into a preallocated
buffer (:data:`gyrostar.loop.record.OUTPUT_DTYPE`; the kernel writes every field but the
latency); this stage stamps their latency (host time from the FIFO read to the emit, µs)
and hands the batch to every sink that serves a consumer waiting for it (callback, UDP,
space packets) in one call.

Sinks that keep records rather than react to them (``block = True``: the run log's
recorder, an in-memory keeper) get them in blocks of :attr:`OutputStage.block_rows`
consecutive records (50 ms at 400 Hz; handed over at the next batch), and the rest at
:meth:`OutputStage.flush` (the loop's close): one hand-over per block instead of one per
gyro sample, so the 400 Hz path touches their code and memory once every 20 samples.
"""

from __future__ import annotations

from . import record as R

BLOCK_ROWS = 20        # records per hand-over to the keeping sinks (50 ms at 400 Hz)


class OutputStage:
    def __init__(self, sinks, lat_clock, capacity: int = 256, block_rows: int = BLOCK_ROWS):
        self.now_sinks = [s for s in sinks if not getattr(s, "block", False)]
        self.block_sinks = [s for s in sinks if getattr(s, "block", False)]
        self.lat_clock = lat_clock
        self.buf = R.empty(capacity)
        self.block_rows = max(1, min(int(block_rows), capacity))
        self._latency = self.buf["latency_us"]    # a field view made once (making one costs µs)
        self._end = 0          # rows of the buffer emitted and not yet handed to the keeping sinks
        self._last = -1        # row of the newest record emitted
        self._t_ns = 0         # its sample time (ns): the block's time stamp
        self.count = 0

    @property
    def last(self):
        """The newest record emitted (None before the first): a view into the buffer, valid
        until the next step (copy it to keep it)."""
        return self.buf[self._last] if self._last >= 0 else None

    def batch(self, n: int):
        """The next ``n`` free records of the buffer, for the kernel to write (n ≤ capacity);
        they may be emitted in parts, in order (:meth:`emit`). A block of ``block_rows`` or
        more emitted records goes to the keeping sinks here, before the new rows, so the rows
        of a batch never move while it is emitted."""
        if self._end >= self.block_rows or self._end + n > len(self.buf):
            self.flush()
        return self.buf[self._end:self._end + n]

    def emit(self, out, t_read: float, t_last: float) -> None:
        """Stamp latency (from ``t_read``, the FIFO read on the latency clock) and send the
        batch ``out`` (the view :meth:`batch` returned) to the waiting sinks."""
        n = len(out)
        i = self._end
        lat = (self.lat_clock.now() - t_read) * 1e6
        if n == 1:
            self._latency[i] = lat
        else:
            self._latency[i:i + n] = lat
        t_ns = int(t_last * 1e9)
        for sink in self.now_sinks:
            sink.put(out, t_ns)
        self._end = i + n
        self._last = i + n - 1
        self._t_ns = t_ns
        self.count += n

    def flush(self) -> None:
        """Hand the records emitted since the last block to the keeping sinks."""
        if self._end:
            block = self.buf[:self._end]
            self._end = 0
            for sink in self.block_sinks:
                sink.put(block, self._t_ns)
