"""The gyrostar log format: append-only records, each with its own CRC-32C.

File layout (all integers little-endian)::

    file   = MAGIC (8 bytes b"GYSTLOG1") record*
    record = SYNC (u8 0xA5) kind (u8) channel (u16) length (u32) t_ns (i64)
             payload (length bytes) crc (u32, CRC-32C of the 16 header bytes + payload)

``t_ns`` is the host time of the event in integer nanoseconds (monotonic clock, or the
simulated clock on a simulated flatsat). ``channel`` tells devices apart (0 = the head
link, 1 = the gyro bus, ...). The writer keeps records in a user-space buffer and
``write(2)``\\ s it to the kernel every ``flush_bytes`` bytes or ``flush_s`` seconds (from a
writer thread with ``background=True``), so a SIGKILL loses at most that unflushed tail;
``fsync`` (power loss) is optional. A reader skips a corrupt stretch to the next record
whose sync byte and CRC hold (reporting offset and length) and reports a cut-off tail.
"""

from __future__ import annotations

import json
import os
import struct
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import crc32c

from ..errors import ConfigError, GyrostarError

MAGIC = b"GYSTLOG1"
SYNC = 0xA5
SYNC_BYTE = bytes([SYNC])
HEADER = struct.Struct("<BBHIq")
CRC = struct.Struct("<I")
_F8_RECORD = struct.Struct("<BBHIqd")     # HEADER + one f8 payload
MAX_PAYLOAD = 64 * 1024 * 1024

# record kinds
META = 1      # JSON: config, scenario, versions, output dtype description
TX = 2        # bytes host -> device (link channel)
RX = 3        # bytes device -> host (link channel)
BUS = 4       # one register-bus transaction (see taps.encode_bus)
CLOCK = 5     # one clock reading: f8 seconds
OUTPUT = 6    # one or more loop output records (raw bytes of gyrostar.loop.record.OUTPUT_DTYPE)
EVENT = 7     # JSON: a notable event (mode change, fault injected, reconnect, ...)
TRUTH = 8     # simulator truth (raw bytes of gyrostar.loop.record.TRUTH_DTYPE)
KIND_NAMES = {META: "meta", TX: "tx", RX: "rx", BUS: "bus", CLOCK: "clock", OUTPUT: "output",
              EVENT: "event", TRUTH: "truth"}

CH_HEAD = 0
CH_GYRO = 1
CH_LATENCY = 2   # CLOCK records of the clock that times sample-to-output latency


@dataclass(frozen=True)
class Record:
    kind: int
    channel: int
    t_ns: int
    payload: bytes


class LogWriteError(GyrostarError):
    """The log could not be written (disk full, file too large, I/O error): the run stops,
    the log keeps every record written before. Not a :class:`DeviceError`: no loop stage
    may take it for a device's failure and carry on."""

    exit_code = 3


class LogWriter:
    """Append records to a log file; thread-safe (a link reader thread may record too).

    A failed write (``OSError``) is kept in :attr:`error`: from then on records are dropped
    (the disk takes no more), nothing raises on the recording threads, and the owner stops
    the run at its next check (:meth:`failure`)."""

    def __init__(self, path: str | Path, flush_bytes: int = 64 * 1024, flush_s: float = 0.05,
                 fsync: bool = False, background: bool = False):
        self.path = Path(path)
        self.flush_bytes = int(flush_bytes)
        self.flush_s = float(flush_s)
        self.fsync = fsync
        # background: the size/age flushes run on a writer thread, so a real-time caller of
        # append() never waits for the disk; flush() and close() still write at once
        self.background = bool(background)
        self._lock = threading.Lock()          # the buffer
        self._wlock = threading.RLock()        # the file: writes in buffer order (close drains inside it)
        self._wake = threading.Event()
        self._writer: threading.Thread | None = None
        self._buf = bytearray()
        self._last_flush = time.monotonic()
        self.records = 0
        self.bytes_written = 0
        self.error: OSError | None = None
        # tee(chunk): called with each run of whole records as it goes to the kernel (on the
        # thread that drains: the writer thread with ``background``); it must not block
        self.tee = None
        self._fd = os.open(self.path, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_APPEND, 0o644)
        self._write_all(MAGIC)

    def append(self, kind: int, payload: bytes | bytearray | memoryview, channel: int = 0,
               t_ns: int = 0) -> None:
        """Add one record; it reaches the kernel at the next flush."""
        if type(payload) is not bytes:
            payload = bytes(payload)
        if len(payload) > MAX_PAYLOAD:
            raise ValueError(f"log record of {len(payload)} bytes exceeds {MAX_PAYLOAD}")
        head = HEADER.pack(SYNC, kind, channel, len(payload), int(t_ns))
        self._add(head, payload, crc32c.crc32c(payload, crc32c.crc32c(head)))

    def append_rows(self, kind: int, rows, channel: int = 0, t_ns: int = 0) -> int:
        """Add a numpy array of fixed-size rows as consecutive records of whole rows, each at
        most :data:`MAX_PAYLOAD` bytes: a reader joins them (``b"".join`` of the payloads of
        that kind). A run's truth at every output is one such array — 88 bytes a row, past
        the record limit after 32 min at 400 Hz. Returns the count of records added."""
        per = max(1, MAX_PAYLOAD // max(rows.dtype.itemsize, 1))
        starts = range(0, len(rows), per)
        for lo in starts:
            self.append(kind, rows[lo:lo + per].tobytes(), channel=channel, t_ns=t_ns)
        return len(starts)

    def append_f8(self, kind: int, value: float, channel: int, t_ns: int) -> None:
        """Add one record whose payload is one f8 (a clock reading): the same bytes as
        ``append(kind, struct.pack("<d", value), channel, t_ns)``, packed and checked in one go."""
        rec = _F8_RECORD.pack(SYNC, kind, channel, 8, t_ns, value)
        self._add(rec, b"", crc32c.crc32c(rec))

    def _add(self, head: bytes, payload: bytes, crc: int) -> None:
        with self._lock:
            if self._fd < 0:
                raise ValueError(f"log {self.path} is closed")
            if self.error is not None:
                return
            buf = self._buf
            buf += head
            if payload:
                buf += payload
            buf += CRC.pack(crc)
            self.records += 1
            due = len(buf) >= self.flush_bytes or time.monotonic() - self._last_flush >= self.flush_s
        if not due:
            return
        if not self.background:
            self.flush()
            return
        if self._writer is None:
            self._start_writer()
        self._wake.set()

    def meta(self, obj: dict, t_ns: int = 0) -> None:
        self.append(META, json.dumps(obj, sort_keys=True).encode(), t_ns=t_ns)

    def event(self, obj: dict, t_ns: int = 0) -> None:
        self.append(EVENT, json.dumps(obj, sort_keys=True).encode(), t_ns=t_ns)

    def flush(self) -> None:
        """Hand every buffered record to the kernel now (:class:`LogWriteError` if it fails)."""
        self._drain()
        if self.error is not None:
            raise self.failure()

    def failure(self) -> LogWriteError:
        """The error to stop a run with, once :attr:`error` is set."""
        err = self.error
        why = (err.strerror or str(err)) if err is not None else "unknown error"
        return LogWriteError(f"log {self.path}: write failed after {self.bytes_written} bytes ({why}); "
                             "the run stopped, the log keeps what was written before")

    def _drain(self) -> bool:
        """Take the buffer (under the buffer lock, O(1)) and write it outside that lock, in
        buffer order (the file lock); False once the log is closed or failed."""
        with self._wlock:
            with self._lock:
                if self._fd < 0 or self.error is not None:
                    return False
                data, self._buf = self._buf, bytearray()
                self._last_flush = time.monotonic()
            if data:
                try:
                    self._write_all(data)
                    if self.fsync:
                        os.fsync(self._fd)
                except OSError as exc:
                    self.error = exc
                    return False
                if self.tee is not None:
                    self.tee(data)
        return True

    def _start_writer(self) -> None:
        with self._lock:
            if self._writer is None and self._fd >= 0:
                self._writer = threading.Thread(target=self._write_behind, name="log-writer", daemon=True)
                self._writer.start()

    def _write_behind(self) -> None:
        """Writer thread: drain every ``flush_s``, or when an append finds a flush due."""
        from ..realtime import join_realtime, loop_priority

        rt = False
        while True:
            self._wake.wait(self.flush_s)
            self._wake.clear()
            if not rt and loop_priority():
                rt = join_realtime(3)     # never preempted by the host while holding the interpreter lock
            if not self._drain():
                return

    def _write_all(self, data) -> None:
        view = memoryview(data)
        while view:
            n = os.write(self._fd, view)
            self.bytes_written += n
            view = view[n:]

    def close(self) -> None:
        """Write what is buffered and close (a failed log is closed as it is; never raises
        for the disk: :attr:`error` tells)."""
        with self._wlock:
            self._drain()
            with self._lock:
                if self._fd >= 0:
                    try:
                        os.fsync(self._fd)
                    except OSError as exc:
                        self.error = self.error or exc
                    os.close(self._fd)
                    self._fd = -1
        if self._writer is not None:
            self._wake.set()
            self._writer.join(timeout=2.0)
            self._writer = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


@dataclass
class ReadReport:
    """What a read found: intact records, corrupt stretches skipped in the middle of the
    file (``skipped``: ``(offset, bytes, reason)`` each) and an unusable tail (a log cut
    short by a crash or a kill)."""

    records: int = 0
    good_bytes: int = 0
    ignored_tail_bytes: int = 0
    tail_reason: str = ""
    skipped: list = field(default_factory=list)

    @property
    def skipped_bytes(self) -> int:
        return sum(n for _, n, _ in self.skipped)

    def describe(self) -> str:
        """One human line, or "" when every byte was read."""
        parts = []
        if self.skipped:
            where = ", ".join(f"{n} at byte {off}" for off, n, _ in self.skipped[:3])
            more = f" and {len(self.skipped) - 3} more" if len(self.skipped) > 3 else ""
            parts.append(f"{self.skipped_bytes} corrupt bytes skipped in {len(self.skipped)} place(s) "
                         f"({where}{more})")
        if self.ignored_tail_bytes:
            parts.append(f"{self.ignored_tail_bytes} bytes of cut-off tail ignored at byte {self.good_bytes} "
                         f"({self.tail_reason})")
        return "; ".join(parts)


def _check_record(data, pos: int, end: int) -> tuple[int, str]:
    """(end of the record at ``pos``, "") if it is intact, else (-1, why not)."""
    if end - pos < HEADER.size + CRC.size:
        return -1, "truncated record header"
    sync, _kind, _channel, length, _t = HEADER.unpack_from(data, pos)
    if sync != SYNC or length > MAX_PAYLOAD:
        return -1, f"bad record header at byte {pos}"
    stop = pos + HEADER.size + length
    if stop + CRC.size > end:
        return -1, "truncated record payload"
    (crc,) = CRC.unpack_from(data, stop)
    if crc32c.crc32c(data[pos:stop]) != crc:
        return -1, f"CRC mismatch at byte {pos}"
    return stop + CRC.size, ""


def _resync(data, pos: int, end: int) -> int:
    """Offset of the next intact record after ``pos`` (a sync byte whose record's CRC
    holds), or -1 if none follows."""
    while True:
        pos = data.find(SYNC_BYTE, pos + 1, end)
        if pos < 0:
            return -1
        if _check_record(memoryview(data), pos, end)[0] > 0:
            return pos


def read_records(path: str | Path, report: ReadReport | None = None, on_progress=None) -> Iterator[Record]:
    """Yield every intact record. A corrupt stretch (a flipped byte, a torn write) is skipped
    up to the next intact record and listed in ``report.skipped``; bytes after the last
    intact record are the cut-off tail (``report.ignored_tail_bytes``). ``on_progress(pos,
    size)`` is called now and then with the byte offset reached.

    Raises :class:`ConfigError` if the file cannot be read or is not a gyrostar log at all.
    """
    from ..files import read_regular

    path = Path(path)
    if path.is_dir():
        raise ConfigError(f"log {path} is a folder, not a log file (the run folder's log is flatsat.gslog)")
    # a regular file only (a FIFO or /dev/zero never ends), read up to its size when opened
    data = read_regular(path, "log", max_bytes=None)
    if data[: len(MAGIC)] != MAGIC:
        raise ConfigError(f"{path} is not a gyrostar log (bad magic {data[:8]!r})")
    report = report if report is not None else ReadReport()
    pos = len(MAGIC)
    end = len(data)
    view = memoryview(data)
    next_report = 0
    while pos < end:
        stop, why = _check_record(view, pos, end)
        if stop < 0:
            nxt = _resync(data, pos, end)
            if nxt < 0:
                report.tail_reason = why
                break
            report.skipped.append((pos, nxt - pos, why))
            pos = nxt
            continue
        _sync, kind, channel, length, t_ns = HEADER.unpack_from(view, pos)
        report.records += 1
        yield Record(kind, channel, t_ns, data[pos + HEADER.size: pos + HEADER.size + length])
        pos = stop
        if on_progress is not None and pos >= next_report:
            on_progress(pos, end)
            next_report = pos + (1 << 20)
    report.good_bytes = pos
    report.ignored_tail_bytes = end - pos
    if on_progress is not None:
        on_progress(end, end)


def read_meta(path: str | Path) -> dict:
    """The first META record of a log (the run's description)."""
    for rec in read_records(path):
        if rec.kind == META:
            return json.loads(rec.payload)
    raise ConfigError(f"log {path} has no META record")
