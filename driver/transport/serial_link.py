"""A packet link over any pyserial URL: reader thread + 0x00-delimited packetizer.

:class:`SerialLink` opens ``serial.serial_for_url(url)`` (``/dev/ttyACM0``, ``socket://h:p``,
``rfc2217://``, ``loop://``, ``spy://PORT?file=tap.txt`` for a hex tap, a pty path) or wraps
an already open serial object, and runs :class:`serial.threaded.ReaderThread` with a
:class:`serial.threaded.Packetizer` that splits the byte stream at 0x00 (the COBS frame
delimiter). Each packet (delimiter removed) is queued with the host monotonic time (s) at
which its last chunk arrived, for time synchronisation.
"""

from __future__ import annotations

import queue
import threading
import time

import serial
import serial.threaded

from ..errors import DeviceError, LinkLostError


class _Packets(serial.threaded.Packetizer):
    TERMINATOR = b"\x00"

    def __init__(self, sink: queue.Queue, max_packet: int):
        super().__init__()
        self.sink = sink
        self.max_packet = max_packet
        self.t_chunk = 0.0
        self.lost: Exception | None = None
        self.overlong = 0

    def data_received(self, data):
        self.t_chunk = time.monotonic()
        self.buffer.extend(data)
        while self.TERMINATOR in self.buffer:
            packet, self.buffer = self.buffer.split(self.TERMINATOR, 1)
            if packet:
                self.handle_packet(bytes(packet))
        if len(self.buffer) > self.max_packet:  # garbage with no delimiter: drop, count it
            self.overlong += 1
            self.buffer.clear()

    def handle_packet(self, packet: bytes) -> None:
        self.sink.put((self.t_chunk, packet))

    def connection_lost(self, exc):
        self.lost = exc or DeviceError("serial link closed")
        self.sink.put((time.monotonic(), None))


class _Reader(serial.threaded.ReaderThread):
    """``ReaderThread`` that also treats an ``OSError`` (a pty or USB device gone: EIO from
    ``in_waiting``) as the connection lost, instead of dying with an unhandled exception."""

    def run(self):
        from ..realtime import join_realtime

        join_realtime()      # just below a real-time loop: it holds the interpreter lock at times
        if not hasattr(self.serial, "cancel_read"):
            self.serial.timeout = 1
        self.protocol = self.protocol_factory()
        self.protocol.connection_made(self)
        self._connection_made.set()
        error = None
        while self.alive and self.serial.is_open:
            try:
                data = self.serial.read(self.serial.in_waiting or 1)
            except (serial.SerialException, OSError, TypeError) as exc:
                error = exc
                break
            if data:
                try:
                    self.protocol.data_received(data)
                except Exception as exc:  # noqa: BLE001 - reported as the reason the link went down
                    error = exc
                    break
        self.alive = False
        self.protocol.connection_lost(error)
        self.protocol = None


class SerialLink:
    """Send raw (already framed) bytes; receive 0x00-delimited packets with arrival times."""

    def __init__(self, url_or_port, baudrate: int = 921600, max_packet: int = 1 << 20):
        if isinstance(url_or_port, str):
            try:
                self.port = serial.serial_for_url(url_or_port, baudrate=baudrate, timeout=0.2)
            except (serial.SerialException, OSError, ValueError) as exc:
                raise DeviceError(f"cannot open serial link {url_or_port!r}: {exc}") from exc
            self.url = url_or_port
        else:
            self.port = url_or_port
            self.url = getattr(url_or_port, "port", None) or repr(url_or_port)
        self._queue: queue.Queue = queue.Queue()
        self._proto = _Packets(self._queue, max_packet)
        self._write_lock = threading.Lock()
        self._thread = _Reader(self.port, lambda: self._proto)
        self._thread.daemon = True
        self._thread.start()
        self._thread.connect()

    def send(self, data: bytes) -> float:
        """Write ``data``; returns the host monotonic time (s) just before the write."""
        if self._proto.lost is not None:
            raise LinkLostError(f"serial link {self.url} is down: {self._proto.lost}")
        with self._write_lock:
            t = time.monotonic()
            try:
                self.port.write(data)
            except (serial.SerialException, OSError) as exc:
                raise LinkLostError(f"write to serial link {self.url} failed: {exc}") from exc
        return t

    def recv(self, timeout: float) -> tuple[float, bytes] | None:
        """Next ``(arrival_time_s, packet)``, or ``None`` after ``timeout`` s without one."""
        try:
            t, packet = self._queue.get(timeout=max(timeout, 0.0))
        except queue.Empty:
            return None
        if packet is None:
            self._queue.put((t, None))  # keep the sentinel for later callers
            raise LinkLostError(f"serial link {self.url} closed: {self._proto.lost}")
        return t, packet

    def drain(self) -> int:
        """Discard queued packets; returns how many were dropped."""
        n = 0
        while True:
            try:
                _, packet = self._queue.get_nowait()
            except queue.Empty:
                return n
            if packet is None:
                self._queue.put((0.0, None))
                return n
            n += 1

    @property
    def overlong(self) -> int:
        """Runs of bytes dropped because no 0x00 delimiter came within ``max_packet`` bytes."""
        return self._proto.overlong

    def close(self) -> None:
        try:
            self._thread.close()
        except Exception:  # noqa: BLE001 - closing an already broken port
            pass

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
