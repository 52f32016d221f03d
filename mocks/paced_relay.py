"""A pty relay that carries bytes at a link preset's line rate, both ways.

The simulated heads (the Python emulator and the firmware's host program) serve a pty at
memory speed; a real head sits behind a UART or USB link. :class:`PacedRelay` stands
between them: the client opens the relay's pty, the relay opens the head's pty, and each
direction is a :class:`gyrostar.transport.linkrate.Wire` — bytes are taken from the sender
only when the wire is free (so a sender that writes faster than the line sees its own queue
fill: the head's back-pressure is real) and handed to the receiver when their wire time
and the transfer latency have passed. Bytes move in slices of ``SLICE_S`` of wire time; a
slice is handed over when its last byte has arrived (so the last byte of a message arrives
exactly on time, earlier ones up to a slice late: never earlier than on the wire). When the
relay wakes late while bytes were still waiting in the sender's queue after its previous read
(measured with ``FIONREAD``, not guessed from a full read), the wire is taken to have kept
sending those bytes from when it fell free: the relay reads the ones the line would have sent
in the missed time, so its own scheduling delays (a loaded host) do not lower the line rate.
Only bytes seen waiting are sent early so; a message written after the last read starts on
the wire when the relay reads it, never at a time before it was written.

:func:`start_relay` runs it in a forked child process, away from the loop's interpreter
lock; ``set_faults`` corrupts the head → client bytes (:class:`~gyrostar.mocks.faults.ByteFaults`).
"""

from __future__ import annotations

import fcntl
import multiprocessing as mp
import os
import select
import struct
import termios
import time
import tty
from collections import deque

from gyrostar.cli.interrupt import ignore_in_child, signals_held
from gyrostar.errors import DeviceError
from gyrostar.transport.linkrate import LinkPreset, Wire, preset

SLICE_S = 1e-3       # wire time per read from a sender (UART 921k: 92 B; usb-fs: 900 B, one USB frame)


class LinkDirection:
    """One direction of the relay: reads the sender ``src`` a slice at a time onto a
    :class:`Wire` and holds each slice (``pending``) until its delivery time."""

    def __init__(self, src: int, dst: int, link: LinkPreset, clock=time.monotonic):
        self.src, self.dst, self.clock = src, dst, clock
        self.wire = Wire(link)
        self.chunk = max(1, int(link.bytes_per_s * SLICE_S))
        self.pending: deque = deque()       # (delivery time, bytes)
        self.mangle = None
        self.backlog = 0                     # bytes left in the sender's queue at the last read
        self.backlog_t = float("-inf")       # when they were counted (s, on ``clock``)

    def waiting(self) -> int:
        """Bytes the sender has written that the relay has not yet read (``FIONREAD``)."""
        try:
            return struct.unpack("i", fcntl.ioctl(self.src, termios.FIONREAD, b"\0\0\0\0"))[0]
        except OSError:
            return 0

    def take(self, now: float) -> bool:
        """Read the sender's next slice at ``now`` (s, ``clock``'s timeline) and queue it for
        delivery at its wire time; ``False`` when the sender has closed."""
        t, n = now, self.chunk
        if self.backlog > 0:      # bytes seen waiting at the last read: the line kept sending them
            start = max(self.wire.busy_until, self.backlog_t)
            missed = int(max(0.0, now - start) * self.wire.link.bytes_per_s)
            n = min(self.backlog, self.chunk + min(missed, 1 << 16))
            t = start
        try:
            data = os.read(self.src, n)
        except OSError:
            return False
        if not data:
            return False
        self.backlog, self.backlog_t = self.waiting(), self.clock()
        self.pending.append((self.wire.transmit(len(data), t), data))
        return True


class PacedRelay:
    """Relay between a new pty (``path``, for the client) and the head's pty ``target``."""

    def __init__(self, target: str, link: LinkPreset | str):
        self.link = preset(link) if isinstance(link, str) else link
        self.master, self.slave = os.openpty()
        tty.setraw(self.slave)
        self.path = os.ttyname(self.slave)
        self.head = os.open(target, os.O_RDWR | os.O_NOCTTY)
        tty.setraw(self.head)
        self.up = LinkDirection(self.master, self.head, self.link)     # client → head
        self.down = LinkDirection(self.head, self.master, self.link)   # head → client

    def run(self, control=None, stop_when=None) -> None:
        """Serve until a side closes, ``control`` (a Connection) says stop, or ``stop_when()``."""
        dirs = (self.up, self.down)
        ctl = [control] if control is not None else []
        while True:
            now = time.monotonic()
            for d in dirs:
                while d.pending and d.pending[0][0] <= now:
                    data = d.pending.popleft()[1]
                    if d.mangle is not None:
                        data = d.mangle(data)
                    try:
                        os.write(d.dst, data)
                    except OSError:
                        return
            ready = [d.src for d in dirs if d.wire.busy_until <= now]
            wake = [d.pending[0][0] for d in dirs if d.pending]
            wake += [d.wire.busy_until for d in dirs if d.wire.busy_until > now]
            timeout = min([0.05] + [max(0.0, w - now) for w in wake])
            try:
                r, _, _ = select.select(ready + ctl, [], [], timeout)
            except (OSError, ValueError):
                return
            if stop_when is not None and stop_when():
                return
            for d in dirs:
                if d.src in r and not d.take(time.monotonic()):
                    return
            if ctl and control in r:
                try:
                    cmd, arg = control.recv()
                except (EOFError, OSError):
                    return
                if cmd == "stop":
                    return
                if cmd == "faults":             # ByteFaults keyword arguments, or None
                    from .faults import ByteFaults

                    self.down.mangle = None if arg is None else ByteFaults(**({"seed": 7} | arg)).mutate
                elif cmd == "stats":
                    control.send({"up_bytes": self.up.wire.bytes_sent, "down_bytes": self.down.wire.bytes_sent})

    def close(self) -> None:
        for fd in (self.master, self.slave, self.head):
            try:
                os.close(fd)
            except OSError:
                pass


def _relay_child(conn, target, link, parent_pid):
    ignore_in_child()
    try:
        relay = PacedRelay(target, link)
    except OSError as exc:
        conn.send(("error", f"cannot open {target}: {exc}"))
        return
    conn.send(("ok", relay.path))
    relay.run(conn, stop_when=lambda: os.getppid() != parent_pid)
    relay.close()


class RelayProcess:
    """A :class:`PacedRelay` in a forked child; ``path`` is the pty the client opens."""

    def __init__(self, target: str, link: LinkPreset | str):
        ctx = mp.get_context("fork")
        self.conn, child = ctx.Pipe()
        self.link = preset(link) if isinstance(link, str) else link
        self.proc = ctx.Process(target=_relay_child, args=(child, target, self.link, os.getpid()),
                                name="link-relay", daemon=True)
        with signals_held():      # the child ignores SIGINT (the parent stops it) before any signal can reach it
            self.proc.start()
        if not self.conn.poll(10.0):
            self.close()
            raise DeviceError("the link relay did not start")
        status, arg = self.conn.recv()
        if status != "ok":
            self.close()
            raise DeviceError(f"link relay: {arg}")
        self.path = arg

    def set_faults(self, settings: dict | None) -> None:
        """Head → client byte faults: :class:`~gyrostar.mocks.faults.ByteFaults` keyword
        arguments (corruption, drops, garbage bursts before a chunk), or None to stop."""
        self.conn.send(("faults", settings))

    def stats(self) -> dict:
        """Bytes carried so far each way: ``up_bytes`` (client → head), ``down_bytes``."""
        self.conn.send(("stats", None))
        if not self.conn.poll(2.0):
            raise DeviceError("link relay did not answer")
        return self.conn.recv()

    def close(self) -> None:
        try:
            if self.proc.is_alive():
                self.conn.send(("stop", None))
        except OSError:
            pass
        self.proc.join(timeout=2.0)
        if self.proc.is_alive():
            self.proc.kill()
            self.proc.join(timeout=1.0)


def start_relay(target: str, link: LinkPreset | str) -> RelayProcess:
    """Pace the head on pty ``target`` at ``link`` (a preset or its name)."""
    return RelayProcess(target, link)
