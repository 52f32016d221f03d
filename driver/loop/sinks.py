"""Output sinks: where the loop's 400 Hz output records go.

Each sink has ``put(records, t_ns)`` (an array of :data:`~gyrostar.loop.record.OUTPUT_DTYPE`
produced in one loop step, or a block of consecutive steps for a sink whose ``block`` is
True) and ``close()``. They never block the loop for long: the UDP
sink drops datagrams the kernel refuses (counted), the recorder buffers in user space.
"""

from __future__ import annotations

import struct

import numpy as np

from ..errors import ConfigError
from ..recording import logfile as lf
from ..telemetry.packets import SpacePacketSink  # noqa: F401  (CCSDS Space Packets: one more sink)
from ..telemetry.udp import open_udp
from .record import OUTPUT_DTYPE, UDP_MAGIC

_UDP_HEAD = struct.Struct("<4sHH")
UDP_MAX_RECORDS = (65507 - _UDP_HEAD.size) // OUTPUT_DTYPE.itemsize


class CallbackSink:
    """Call ``fn(records)`` with each step's records (a read-only view: copy to keep)."""

    def __init__(self, fn):
        self.fn = fn

    def put(self, records: np.ndarray, t_ns: int = 0) -> None:
        if len(records):
            self.fn(records)

    def close(self) -> None:
        pass


class ArraySink:
    """Keep every record in one array made for the whole run (``capacity`` rows, its pages
    not yet touched); takes them in blocks (:class:`gyrostar.loop.outputs.OutputStage`).

    ``put`` copies the step's records as raw bytes into the next rows (about 1 µs for one
    record, where ``records.copy()`` into a list costs 5 µs). The array's pages are touched
    ahead of the records, ``chunk_rows`` rows at a time (512: 1.28 s at 400 Hz, 412 kB, under
    1 ms), by :meth:`reserve`, which a runner calls between steps — a page fault inside a
    400 Hz step costs ~10 µs, and the memory is taken as the run goes rather than at its
    start. A step never allocates unless more records come than ``capacity`` (then the
    array doubles, in that put: a caller that sized it too small pays there). Growing by
    doubling from 2^20 rows stalled the step that crossed them (43.7 min at 400 Hz) for
    about 4 s while 1.7 GB were allocated, touched and copied.
    :attr:`records` is the run so far (a view).
    """

    block = True

    def __init__(self, capacity: int = 1 << 16, chunk_rows: int = 1 << 9):
        self.n = 0
        self.chunk_rows = max(1, int(chunk_rows))
        self.grown_in_put = 0          # times a put had to grow the array (none when sized for the run)
        self.touched_in_put = 0        # rows a put had to touch itself (none when reserved)
        self._buf = np.empty(max(int(capacity), 1), OUTPUT_DTYPE)      # address space only, for now
        self._raw = self._buf.view(np.uint8).reshape(len(self._buf), OUTPUT_DTYPE.itemsize)
        self._touched = 0
        self.reserve()

    def _touch(self, upto: int) -> None:
        upto = min(upto, len(self._buf))
        if upto > self._touched:
            self._raw[self._touched:upto].fill(0)
            self._touched = upto

    def reserve(self, spare_rows: int | None = None) -> None:
        """Touch the pages of the next ``spare_rows`` rows (default one chunk) that are not
        yet: a runner calls it between steps so the next puts find their memory ready."""
        spare = self.chunk_rows if spare_rows is None else int(spare_rows)
        while self._touched < min(self.n + spare, len(self._buf)):
            self._touch(self._touched + self.chunk_rows)

    def put(self, records: np.ndarray, t_ns: int = 0) -> None:
        k = len(records)
        i = self.n
        if i + k > len(self._buf):
            self.grown_in_put += 1
            self._grow(i + k)
        if i + k > self._touched:
            self.touched_in_put += i + k - self._touched
            self._touch(i + k)
        self._raw[i:i + k] = records.view(np.uint8).reshape(k, OUTPUT_DTYPE.itemsize)
        self.n = i + k

    def _grow(self, need: int) -> None:
        buf = np.empty(max(need, 2 * len(self._buf)), OUTPUT_DTYPE)
        raw = buf.view(np.uint8).reshape(len(buf), OUTPUT_DTYPE.itemsize)
        raw[:self.n] = self._raw[:self.n]
        self._buf, self._raw, self._touched = buf, raw, self.n

    @property
    def records(self) -> np.ndarray:
        """The records kept so far (a view: valid until the next ``put``)."""
        return self._buf[:self.n]

    def close(self) -> None:
        pass


class RecorderSink:
    """Append records to a log, one OUTPUT record per block the output stage hands over
    (its ``t_ns``: the block's last sample time)."""

    block = True

    def __init__(self, writer: lf.LogWriter):
        self.writer = writer

    def put(self, records: np.ndarray, t_ns: int = 0) -> None:
        if len(records):
            self.writer.append(lf.OUTPUT, records.tobytes(), t_ns=t_ns)

    def close(self) -> None:
        """Hand the last records to the kernel (a log that failed is left to its owner:
        :attr:`LogWriter.error`)."""
        if self.writer.error is None:
            self.writer.flush()


class UdpSink:
    """Send records as UDP datagrams (default loopback only).

    Datagram: ``b"GYS1"``, u16 record size, u16 count, then ``count`` raw records
    (little-endian OUTPUT_DTYPE). Decode with :func:`decode_datagram`.
    """

    def __init__(self, host: str = "127.0.0.1", port: int = 47800, allow_remote: bool = False,
                 host_key: str = "outputs.udp_host"):
        self.sock, self.addr = open_udp(host, port, allow_remote, "UDP output", host_key)
        self.sent = 0
        self.dropped = 0

    def put(self, records: np.ndarray, t_ns: int = 0) -> None:
        for start in range(0, len(records), UDP_MAX_RECORDS):
            chunk = records[start: start + UDP_MAX_RECORDS]
            payload = _UDP_HEAD.pack(UDP_MAGIC, OUTPUT_DTYPE.itemsize, len(chunk)) + chunk.tobytes()
            try:
                self.sock.sendto(payload, self.addr)
                self.sent += len(chunk)
            except OSError:   # no listener buffer, EAGAIN, ECONNREFUSED: count, never stall
                self.dropped += len(chunk)

    def close(self) -> None:
        self.sock.close()


def decode_datagram(data: bytes) -> np.ndarray:
    """Records of one UDP datagram from :class:`UdpSink` (raises ConfigError if malformed)."""
    if len(data) < _UDP_HEAD.size:
        raise ConfigError("UDP datagram shorter than its header")
    magic, size, count = _UDP_HEAD.unpack_from(data)
    if magic != UDP_MAGIC or size != OUTPUT_DTYPE.itemsize:
        raise ConfigError(f"not a gyrostar output datagram (magic {magic!r}, record size {size})")
    if len(data) != _UDP_HEAD.size + size * count:
        raise ConfigError(f"datagram length {len(data)} does not match {count} records")
    return np.frombuffer(data, OUTPUT_DTYPE, count, _UDP_HEAD.size)
