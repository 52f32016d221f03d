"""Fault injection for every mock: register buses (I2C/SPI) and byte streams (serial links).

:class:`FaultyBus` wraps anything with smbus2.SMBus's or spidev.SpiDev's methods (a fake or a
real bus) and, per transaction, can:

* NACK — raise ``OSError(errno.EREMOTEIO)`` (121) for the next ``n`` transactions or while a
  simulated-time window is open (the transaction never reaches the device);
* stick — reads return a constant byte (a stuck SDA/MISO line) without reaching the device;
* corrupt — flip a random bit in read bytes with a given probability;
* disconnect — every transaction fails with ``OSError(errno.ENODEV)`` until reconnected;
* fail part-way — a read reaches the device, which shifts out only the first part of the
  bytes (a FIFO pops the frames those carry), then the transfer fails with
  ``OSError(errno.ETIMEDOUT)`` (an I2C clock-stretch timeout, an aborted SPI transfer).

:class:`ByteFaults` mutates a byte stream on its way out: corrupt (bit flips), drop
(bytes vanish), garbage (a burst of random bytes, delimiters included, written before a
write), delay (each write is held back by a fixed delay plus uniform jitter);
``disconnected`` makes the writer stop. Counters record what was injected, ``mangled`` the
writes (frames) that reached the wire changed.
"""

from __future__ import annotations

import errno
import random
import threading
import time

TRANSACTIONS = ("read_byte", "write_byte", "read_byte_data", "write_byte_data", "read_word_data",
                "read_i2c_block_data", "write_i2c_block_data", "i2c_rdwr", "xfer2", "xfer", "readbytes")
READS = {"read_byte", "read_byte_data", "read_word_data", "read_i2c_block_data", "xfer2", "xfer", "readbytes"}


class FaultyBus:
    def __init__(self, inner, clock=None, seed: int = 0):
        self.inner = inner
        self.clock = clock
        self.rng = random.Random(seed)
        self.lock = threading.Lock()
        self._nack_left = 0
        self._nack_windows: list[tuple[float, float]] = []
        self.stuck_byte: int | None = None
        self.corrupt_p = 0.0
        self.disconnected = False
        self._midway: list = []    # [reads left, fraction delivered, minimum data bytes]
        self.injected = {"nack": 0, "stuck": 0, "corrupt": 0, "disconnect": 0, "midway": 0}

    # --- arming -------------------------------------------------------------------------------
    def nack_next(self, n: int) -> None:
        """NACK the next ``n`` transactions."""
        self._nack_left = n

    def nack_between(self, t0: float, t1: float) -> None:
        """NACK every transaction while ``t0 <= clock.now() < t1`` (simulated seconds)."""
        self._nack_windows.append((t0, t1))

    def stick(self, value: int | None = 0xFF) -> None:
        """Reads return ``value`` for every byte (``None`` to release)."""
        self.stuck_byte = value

    def fail_midway_next(self, n: int = 1, fraction: float = 0.5, min_bytes: int = 7) -> None:
        """The next ``n`` reads of at least ``min_bytes`` data bytes (FIFO bursts, not status
        bytes) fail part-way: the device delivers the first ``fraction`` of the bytes, then
        the call raises ``OSError(errno.ETIMEDOUT)`` and the caller gets nothing."""
        if not 0.0 < fraction < 1.0:
            raise ValueError(f"fraction must be in (0, 1), got {fraction}")
        self._midway = [n, fraction, min_bytes]

    def corrupt(self, p: float) -> None:
        self.corrupt_p = p

    def disconnect(self) -> None:
        self.disconnected = True

    def reconnect(self) -> None:
        self.disconnected = False

    # --- interception -------------------------------------------------------------------------
    def _gate(self) -> None:
        with self.lock:
            if self.disconnected:
                self.injected["disconnect"] += 1
                raise OSError(errno.ENODEV, "No such device (bus disconnected)")
            if self._nack_left > 0:
                self._nack_left -= 1
                self.injected["nack"] += 1
                raise OSError(errno.EREMOTEIO, "Remote I/O error (NACK)")
            if self._nack_windows and self.clock is not None:
                now = self.clock.now()
                if any(t0 <= now < t1 for t0, t1 in self._nack_windows):
                    self.injected["nack"] += 1
                    raise OSError(errno.EREMOTEIO, "Remote I/O error (NACK)")

    def _mangle(self, data):
        if self.corrupt_p <= 0:
            return data
        out = list(data)
        for i in range(len(out)):
            if self.rng.random() < self.corrupt_p:
                out[i] ^= 1 << self.rng.randrange(8)
                self.injected["corrupt"] += 1
        return out

    def __getattr__(self, name):
        attr = getattr(self.inner, name)
        if name not in TRANSACTIONS:
            return attr

        def call(*args, **kwargs):
            self._gate()
            if self._midway and self._midway[0] > 0 and name in READS | {"i2c_rdwr"}:
                cut = self._cut_short(name, args)
                if cut is not None:
                    self._midway[0] -= 1
                    self.injected["midway"] += 1
                    attr(*cut, **kwargs)
                    raise OSError(errno.ETIMEDOUT, "Connection timed out (transfer aborted part-way)")
            if self.stuck_byte is not None and name in READS | {"i2c_rdwr"}:
                self.injected["stuck"] += 1
                return self._stuck(name, args)
            result = attr(*args, **kwargs)
            if name == "i2c_rdwr" and self.corrupt_p > 0:
                import ctypes

                for msg in args:
                    if msg.flags & 1:
                        data = bytes(self._mangle(bytes(msg)))
                        ctypes.memmove(msg.buf, data, msg.len)
                return result
            if name in ("read_byte", "read_byte_data"):
                return self._mangle([result])[0]
            if name in READS and result is not None:
                if name in ("xfer2", "xfer"):
                    return result[:1] + self._mangle(result[1:])
                return self._mangle(result)
            return result

        return call

    def _cut_short(self, name, args):
        """The arguments of the same read asking for its first ``fraction`` of data bytes, or
        None when the read is shorter than ``min_bytes``."""
        _, fraction, min_bytes = self._midway

        def part(n):
            return max(1, int(n * fraction))

        if name == "read_i2c_block_data" and args[2] >= min_bytes:
            return (args[0], args[1], part(args[2]))
        if name in ("xfer2", "xfer") and len(args[0]) - 1 >= min_bytes:
            return (list(args[0])[:1 + part(len(args[0]) - 1)],)
        if name == "readbytes" and args[0] >= min_bytes:
            return (part(args[0]),)
        if name == "i2c_rdwr" and any(m.flags & 1 and m.len >= min_bytes for m in args):
            from smbus2 import i2c_msg

            return tuple(i2c_msg.read(m.addr, part(m.len)) if m.flags & 1 else m for m in args)
        return None

    def _stuck(self, name, args):
        v = self.stuck_byte
        if name in ("read_byte", "read_byte_data"):
            return v
        if name == "read_word_data":
            return v | v << 8
        if name == "read_i2c_block_data":
            return [v] * args[2]
        if name in ("xfer2", "xfer"):
            return [v] * len(args[0])
        if name == "readbytes":
            return [v] * args[0]
        import ctypes

        for msg in args:  # i2c_rdwr
            if msg.flags & 1:
                ctypes.memmove(msg.buf, bytes([v]) * msg.len, msg.len)
        return None


def precise_wait(dt: float) -> None:
    """Wait ``dt`` s: sleep for the bulk, spin for the last 2 ms (``time.sleep`` alone
    overshoots sub-millisecond delays by ~60 µs, which would bias injected jitter)."""
    end = time.perf_counter() + dt
    if dt > 0.002:
        time.sleep(dt - 0.002)
    while time.perf_counter() < end:
        pass


class JitteredLink:
    """A packet link whose sends are held back by :class:`ByteFaults` after being timestamped
    (jitter on the host→head direction, as a real link adds it after the host's clock read)."""

    def __init__(self, link, faults: ByteFaults):
        self.link = link
        self.faults = faults
        self.url = getattr(link, "url", "?")

    def send(self, data: bytes) -> float:
        t = time.monotonic()
        self.faults.write_through(self.link.send, data)
        return t

    def __getattr__(self, name):
        return getattr(self.link, name)


class ByteFaults:
    """Mutations applied to bytes on a link, deterministic for a given seed."""

    def __init__(self, seed: int = 0, corrupt_p: float = 0.0, drop_p: float = 0.0, delay_s: float = 0.0,
                 jitter_s: float = 0.0, garbage_p: float = 0.0, garbage_len: tuple[int, int] = (8, 64)):
        self.rng = random.Random(seed)
        self.corrupt_p = corrupt_p
        self.drop_p = drop_p
        self.delay_s = delay_s
        self.jitter_s = jitter_s
        self.garbage_p = garbage_p          # probability that a write is preceded by a garbage burst
        self.garbage_len = garbage_len      # burst length range (bytes, inclusive)
        self.disconnected = False
        # delimiters_lost: frame delimiters (0x00) dropped or flipped to another value — each one
        # merges a reply with the next, so the decoder sees one corrupt frame for two mangled replies
        self.injected = {"corrupt": 0, "drop": 0, "delayed": 0, "garbage_bursts": 0, "garbage_bytes": 0,
                         "delimiters_lost": 0}
        self.writes = 0                     # writes passed through
        self.mangled = 0                    # writes whose bytes were changed (corrupt or drop)

    def mangle(self, data: bytes) -> bytes:
        if self.corrupt_p <= 0 and self.drop_p <= 0:
            return data
        out = bytearray()
        for b in data:
            if self.drop_p and self.rng.random() < self.drop_p:
                self.injected["drop"] += 1
                self.injected["delimiters_lost"] += b == 0
                continue
            if self.corrupt_p and self.rng.random() < self.corrupt_p:
                self.injected["delimiters_lost"] += b == 0
                b ^= 1 << self.rng.randrange(8)
                self.injected["corrupt"] += 1
            out.append(b)
        return bytes(out)

    def delay(self) -> float:
        d = self.delay_s + (self.rng.random() * self.jitter_s if self.jitter_s else 0.0)
        if d > 0:
            self.injected["delayed"] += 1
        return d

    def garbage(self) -> bytes:
        """A garbage burst (random bytes, 0x00 delimiters included) or b"" by ``garbage_p``."""
        if self.garbage_p <= 0 or self.rng.random() >= self.garbage_p:
            return b""
        n = self.rng.randint(*self.garbage_len)
        self.injected["garbage_bursts"] += 1
        self.injected["garbage_bytes"] += n
        return bytes(self.rng.randrange(256) for _ in range(n))

    def mutate(self, data: bytes) -> bytes:
        """``data`` corrupted and with bytes dropped, after a garbage burst (no delay): one write."""
        self.writes += 1
        junk = self.garbage()
        out = self.mangle(data)
        if out != data:
            self.mangled += 1
        return junk + out

    def counts(self) -> dict:
        """Writes passed through, writes mangled, and the injected counters."""
        return {"writes": self.writes, "mangled": self.mangled} | self.injected

    def write_through(self, write, data: bytes, sleep=None) -> None:
        """Apply delay, then corruption/drops (and a garbage burst before), then ``write`` the
        result (nothing if disconnected)."""
        if self.disconnected:
            return
        d = self.delay()
        if d > 0:
            (sleep or precise_wait)(d)
        out = self.mutate(data)
        if out:
            write(out)
