"""Recording taps and their replay twins: serial link, register bus, clock.

A tap wraps the object the driver already talks to and records every call's result in a
:class:`~gyrostar.recording.logfile.LogWriter`; the replay twin has the same methods and
answers every call from a log, checking that the driver asks exactly what it asked when
recording (anything else raises :class:`ReplayDivergence`).

* packet link (``send``, ``recv``, ``drain`` of :class:`gyrostar.transport.SerialLink`):
  TX, RX and WAITING records holding the raw frame bytes.
* register bus (:class:`gyrostar.transport.RegisterBus`: ``read(reg, n)``, ``write(reg,
  data)``, over I2C or SPI): BUS records; a failed transaction (``DeviceError``, e.g. a
  NACK) is recorded with its errno and raised again on replay.
* clock (``now() -> float`` seconds): CLOCK records (f8, bit exact).
"""

from __future__ import annotations

import struct
from collections import deque

from ..errors import GyrostarError
from . import logfile as lf

WAITING = 9
lf.KIND_NAMES[WAITING] = "waiting"

# bus operations
OP_READ_BYTE = 1
OP_WRITE_BYTE = 2
OP_READ_BLOCK = 3
OP_WRITE_BLOCK = 4
OP_RDWR = 5
OP_SPI_XFER = 6
_BUS_HEAD = struct.Struct("<BBBB")  # op, addr, reg, errno (0 = ok)
_MSG_HEAD = struct.Struct("<HHH")   # addr, flags, len
I2C_M_RD = 0x0001


class ReplayDivergence(GyrostarError):
    """The driver asked something different from what the log holds at this point."""

    exit_code = 1


def _t_ns(clock) -> int:
    return int(round(clock.last * 1e9)) if clock is not None and clock.last is not None else 0


# --------------------------------------------------------------------------- clock


class RecordingClock:
    """Wrap a clock (``now()`` seconds); record every reading."""

    def __init__(self, clock, writer: lf.LogWriter, channel: int = 0):
        self._clock = clock
        self._w = writer
        self._ch = channel
        self.last: float | None = None

    def now(self) -> float:
        t = float(self._clock.now())
        self.last = t
        self._w.append_f8(lf.CLOCK, t, self._ch, int(round(t * 1e9)) if t == t else 0)
        return t

    def sleep(self, dt: float) -> None:
        self._clock.sleep(dt)

    def __getattr__(self, name):
        return getattr(self._clock, name)


class ReplayClock:
    """Answer ``now()`` from the recorded readings, in order."""

    def __init__(self, readings):
        self._q = deque(readings)
        self.last: float | None = None

    def now(self) -> float:
        if not self._q:
            raise ReplayExhausted("clock readings")
        self.last = self._q.popleft()
        return self.last

    def sleep(self, dt: float) -> None:
        """Waiting is what the recording did; replay does not wait."""

    def remaining(self) -> int:
        return len(self._q)


class ReplayExhausted(GyrostarError):
    """The log has no more recorded answers: the replay reached the end of the log."""


# --------------------------------------------------------------------------- link
_RX = struct.Struct("<Bd")   # status, arrival time (s)
RX_PACKET, RX_TIMEOUT, RX_CLOSED = 0, 1, 2
TX_OK, TX_FAILED = 0, 1


class RecordingLink:
    """Wrap a packet link (:class:`gyrostar.transport.SerialLink` interface: ``send``,
    ``recv``, ``drain``); record every frame's raw bytes in both directions.

    TX payload: u8 status (ok, failed) + f8 send time + the bytes written (+ 0x00 and the
    error text when the write failed). RX payload: u8 status (packet, timeout,
    closed) + f8 arrival time + the bytes between two 0x00 delimiters, as received.
    """

    def __init__(self, link, writer: lf.LogWriter, channel: int = lf.CH_HEAD, clock=None):
        self._link = link
        self._w = writer
        self._ch = channel
        self._clock = clock

    def send(self, data) -> float:
        data = bytes(data)
        try:
            t = self._link.send(data)
        except GyrostarError as exc:
            self._w.append(lf.TX, _RX.pack(TX_FAILED, 0.0) + data + b"\x00" + str(exc).encode(), self._ch,
                           _t_ns(self._clock))
            raise
        self._w.append(lf.TX, _RX.pack(TX_OK, t) + data, self._ch, _t_ns(self._clock))
        return t

    def recv(self, timeout: float):
        try:
            got = self._link.recv(timeout)
        except GyrostarError as exc:
            self._w.append(lf.RX, _RX.pack(RX_CLOSED, 0.0) + str(exc).encode(), self._ch, _t_ns(self._clock))
            raise
        if got is None:
            self._w.append(lf.RX, _RX.pack(RX_TIMEOUT, 0.0), self._ch, _t_ns(self._clock))
            return None
        t, packet = got
        self._w.append(lf.RX, _RX.pack(RX_PACKET, t) + bytes(packet), self._ch, _t_ns(self._clock))
        return got

    def drain(self) -> int:
        n = int(self._link.drain())
        self._w.append(WAITING, struct.pack("<I", n), self._ch, _t_ns(self._clock))
        return n

    def __getattr__(self, name):
        return getattr(self._link, name)


class ReplayLink:
    """A packet link answering ``recv``/``drain`` from the log and checking every ``send``."""

    def __init__(self, records, url: str = "replay"):
        self._q = deque(records)
        self.url = url
        self.overlong = 0

    def _next(self, kind: int, what: str) -> lf.Record:
        if not self._q:
            raise ReplayExhausted(f"link records ({what})")
        rec = self._q.popleft()
        if rec.kind != kind:
            raise ReplayDivergence(f"replay: driver did {what} where the log has "
                                   f"{lf.KIND_NAMES.get(rec.kind, rec.kind)} at t={rec.t_ns} ns")
        return rec

    def recorded_first_seq(self) -> int | None:
        """Sequence number of the next request the recorded client sent (a new client on this
        link starts there, as the recorded one drew it), or None."""
        from ..protocol.errors import FrameError
        from ..protocol.framing import decode_frame

        for rec in self._q:
            if rec.kind == lf.TX:
                try:
                    return decode_frame(rec.payload[_RX.size:].split(b"\x00")[0]).seq
                except FrameError:
                    return None
        return None

    def send(self, data) -> float:
        data = bytes(data)
        rec = self._next(lf.TX, f"send of {len(data)} bytes")
        status, t = _RX.unpack_from(rec.payload)
        body = rec.payload[_RX.size:]
        sent = body[: len(data)]
        if sent != data:
            raise ReplayDivergence(f"replay: driver sent {data[:24].hex()}... but the log has "
                                   f"{body[:24].hex()}... at t={rec.t_ns} ns")
        if status == TX_FAILED:     # links raise only for a lost link
            from ..errors import LinkLostError

            raise LinkLostError(body[len(data) + 1:].decode(errors="replace"))
        return t

    def recv(self, timeout: float):
        rec = self._next(lf.RX, f"recv({timeout})")
        status, t = _RX.unpack_from(rec.payload)
        body = rec.payload[_RX.size:]
        if status == RX_TIMEOUT:
            return None
        if status == RX_CLOSED:
            from ..errors import LinkLostError

            raise LinkLostError(body.decode(errors="replace"))
        return t, body

    def drain(self) -> int:
        return struct.unpack("<I", self._next(WAITING, "drain").payload)[0]

    def close(self) -> None:
        pass

    def remaining(self) -> int:
        return len(self._q)


# --------------------------------------------------------------------------- bus
_BUS = struct.Struct("<BBHh")   # op, reg, length, errno (0 = ok, -1 = error without errno)
OP_READ = 1
OP_WRITE = 2


class RecordingRegisters:
    """Wrap a :class:`gyrostar.transport.RegisterBus` (``read(reg, n)``, ``write(reg, data)``);
    record every transaction: the register, the length, the bytes read or written, and the
    error (a :class:`~gyrostar.errors.DeviceError`, e.g. a NACK) if it failed."""

    def __init__(self, regs, writer: lf.LogWriter, channel: int = lf.CH_GYRO, clock=None):
        self._regs = regs
        self._w = writer
        self._ch = channel
        self._clock = clock

    def _rec(self, op, reg, n, err, data, msg=b""):
        self._w.append(lf.BUS, _BUS.pack(op, reg & 0xFF, n, err) + bytes(data) + msg, self._ch,
                       _t_ns(self._clock))

    def read(self, reg: int, n: int) -> bytes:
        try:
            data = bytes(self._regs.read(reg, n))
        except GyrostarError as exc:
            self._rec(OP_READ, reg, n, _errno(exc), b"", str(exc).encode())
            raise
        self._rec(OP_READ, reg, n, 0, data)
        return data

    def write(self, reg: int, data) -> None:
        data = bytes(data)
        try:
            self._regs.write(reg, data)
        except GyrostarError as exc:
            self._rec(OP_WRITE, reg, len(data), _errno(exc), data, str(exc).encode())
            raise
        self._rec(OP_WRITE, reg, len(data), 0, data)

    def describe(self) -> str:
        return self._regs.describe()

    def __getattr__(self, name):
        return getattr(self._regs, name)


def _errno(exc) -> int:
    code = getattr(exc, "errno", None)
    return int(code) if code else -1


class ReplayRegisters:
    """A RegisterBus that answers from BUS records and checks every request against them."""

    def __init__(self, records, name: str = "replay"):
        self._q = deque(records)
        self.name = name

    def _next(self, op, reg, n, what):
        if not self._q:
            raise ReplayExhausted(f"bus records ({what})")
        rec = self._q.popleft()
        rop, rreg, rn, err = _BUS.unpack_from(rec.payload)
        if (rop, rreg, rn) != (op, reg & 0xFF, n):
            raise ReplayDivergence(f"replay: driver did {what} where the log has op {rop} reg 0x{rreg:02x} "
                                   f"length {rn} at t={rec.t_ns} ns")
        body = rec.payload[_BUS.size:]
        if err:
            from ..errors import DeviceError

            exc = DeviceError(body[n if op == OP_WRITE else 0:].decode(errors="replace"))
            exc.errno = None if err < 0 else err
            raise exc
        return body

    def read(self, reg: int, n: int) -> bytes:
        return self._next(OP_READ, reg, n, f"read(0x{reg:02x}, {n})")

    def write(self, reg: int, data) -> None:
        data = bytes(data)
        logged = self._next(OP_WRITE, reg, len(data), f"write(0x{reg:02x}, {data.hex()})")
        if logged != data:
            raise ReplayDivergence(f"replay: wrote {data.hex()} to 0x{reg:02x}, the log has {logged.hex()}")

    def describe(self) -> str:
        return f"replay of {self.name}"

    def remaining(self) -> int:
        return len(self._q)
