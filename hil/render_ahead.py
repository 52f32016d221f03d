"""A fast run's streamed windows rendered in a child process, ahead of their readout.

In lock-step the head emulator renders frame k+1's windows when its exposure starts, just
after frame k is read out, and the loop steps through frame k before it needs frame k+1's
pixels. Here that render — and the frame's FRAME messages, encoded with the header as it
stood at the exposure's start — goes to a forked copy of the emulator (its sky and scene, the
same code and numbers), and the loop's step runs meanwhile on the other core: the same
bytes, bit for bit. The emulator re-encodes a frame itself when a counter in its header
moved before the readout, as it would in-process.

The child renders requests in the order they are submitted (the scene's attitude and each
frame's noise are what the in-process emulator would have used); an eclipse is forwarded in
that order too. If the child ends, its outstanding renders and all later ones are done in
this process, with one warning line.
"""

from __future__ import annotations

import logging
import multiprocessing as mp
import os
import pickle
import struct
import time
from collections import deque

import numpy as np

from ..cli.interrupt import ignore_in_child, signals_held
from .host_cpus import cpus

log = logging.getLogger(__name__)

# messages (raw bytes: a pickle per frame costs more than the render saves): a kind byte, then
_RENDER, _ECLIPSE, _ORIGIN, _STOP = b"R"[0], b"E"[0], b"O"[0], b"S"[0]
_REQ = struct.Struct("<qdqqi?")    # render: handle, t_start (s), sensor frame, exposure (µs), spans, encode;
#                                    int32 spans (n, 4); then, to encode, the FRAME header fields and format, seq:
_ENC = struct.Struct("<10q")
_HEAD = ("frame", "set_frame", "t_start_us", "t_end_us", "exposure_us", "late_sets", "dropped", "backpressure")
_ANS = struct.Struct("<qq")        # answer: handle, pixels; uint16 pixels in span order; pickled FRAME messages
_ECL = struct.Struct("<?q")        # eclipse: on, the emulator's exposure (µs)
_ORG = struct.Struct("<d")         # scenario origin (host s)
# after each message the child polls the pipe without sleeping this long (s) before it blocks:
# in a fast run the next request comes within ~1 ms of wall time
SPIN_S = 0.002


def usable() -> bool:
    """True when a render process can help: two or more CPUs for this process, and a process
    allowed children (a Dask or multiprocessing worker, one run per CPU, is not)."""
    return cpus() >= 2 and not mp.current_process().daemon


def _child(conn, emu, parent_pid: int) -> None:
    ignore_in_child()          # a terminal's Ctrl-C is the parent's: it stops us, no traceback
    try:
        _serve(conn, emu, parent_pid)
    except Exception:          # noqa: BLE001 — ended quietly: the parent renders from here on, where
        return                 # the same error (the same inputs) surfaces as the run's own


def _serve(conn, emu, parent_pid: int) -> None:
    emu.renderer = None
    emu.scene.truth.on_restart = []     # the parent's forwarders stay with the parent
    # the forked pages touched and the caches warmed now, while the parent starts its loop: not
    # at the first frame (20 ms); the scene is not queried, so its attitudes stay the parent's
    emu.warm_up(emu.scene.truth.q0)
    while True:
        try:
            # the forked child holds the parent's end too, so a killed parent never shows as
            # EOF: watch for being re-parented instead (no orphan renderer)
            if not await_request(conn):
                while not conn.poll(0.5):
                    if os.getppid() != parent_pid:
                        return
            msg = conn.recv_bytes()
        except (EOFError, OSError):
            return
        kind = msg[0]
        if kind == _RENDER:
            handle, t_start, frame, exposure_us, n, enc = _REQ.unpack_from(msg, 1)
            # a writable copy: a read-only array is another type to the compiled kernels
            spans = np.frombuffer(msg, np.int32, n * 4, 1 + _REQ.size).reshape(n, 4).copy()
            encode = _unpack_encode(msg, 1 + _REQ.size + spans.nbytes) if enc else None
            pixels, messages = _render(emu, (spans, t_start, frame, exposure_us, encode))
            conn.send_bytes(_ANS.pack(handle, len(pixels)) + pixels.tobytes()
                            + (pickle.dumps(messages, pickle.HIGHEST_PROTOCOL) if messages is not None else b""))
        elif kind == _ECLIPSE:
            on, exposure_us = _ECL.unpack_from(msg, 1)
            emu.exposure_us = exposure_us
            emu.eclipse(bool(on))
        elif kind == _ORIGIN:
            emu.scene.truth.restart(_ORG.unpack_from(msg, 1)[0])
        elif kind == _STOP:
            return


def await_request(conn, spin_s: float = SPIN_S) -> bool:
    """True once the next request is in the pipe, polled without sleeping for up to ``spin_s``
    (s); False if none came by then. While this process runs, the parent's write wakes no
    sleeper: on this VM a pipe write that must wake the other CPU costs ~25–75 µs of the
    loop's own time, one written to a running reader ~3 µs."""
    end = time.perf_counter() + spin_s
    while not conn.poll(0):
        if time.perf_counter() > end:
            return False
    return True


def _render(emu, req) -> tuple:
    """``(pixels, FRAME messages or None)`` of one request."""
    spans, t_start, frame, exposure_us, encode = req
    pixels = emu.render_windows(spans, t_start, frame, exposure_us)
    if encode is None:
        return pixels, None
    head, fmt, seq = encode
    ids, slices = emu.window_set(spans)
    return pixels, emu.frame_messages(head, ids, slices, pixels, fmt, seq)


def _pack_encode(encode) -> bytes:
    head, fmt, seq = encode
    return _ENC.pack(*(head[k] for k in _HEAD), fmt, seq)


def _unpack_encode(msg: bytes, at: int):
    v = _ENC.unpack_from(msg, at)
    return dict(zip(_HEAD, v[:8])), v[8], v[9]


class RenderAhead:
    """The head emulator's stream renders in a forked copy of it (``HeadEmulator.renderer``)."""

    def __init__(self, emu):
        self.emu = emu
        ctx = mp.get_context("fork")
        self._conn, child_conn = ctx.Pipe()
        self._proc = ctx.Process(target=_child, args=(child_conn, emu, os.getpid()), name="head-render",
                                 daemon=True)
        with signals_held():   # the child ignores SIGINT (SIGTERM: default) before any signal reaches it
            self._proc.start()
        child_conn.close()
        self._next = 0
        self._sent: deque = deque()        # (handle, request) sent and not yet answered, in order
        self._done: dict = {}              # handle → (pixels, messages) answered before asked for
        self._dropped: set = set()         # handles nobody will ask for
        self.local = False                 # the child has ended: renders done here
        self.failed: str | None = None     # why it ended (a run's warning line says it)
        self.wait_s = 0.0                  # wall s spent waiting for the child's answers
        emu.scene.truth.on_restart.append(self.origin)

    @property
    def pid(self) -> int | None:
        """The child's process id (None once closed)."""
        return None if self._proc is None else self._proc.pid

    # -- the emulator's side -------------------------------------------------------------
    def submit(self, spans: np.ndarray, t_start: float, frame: int, exposure_us: int, encode=None) -> int:
        """Start a render (``HeadEmulator.render_windows`` arguments; ``encode``: (FRAME header
        fields, pixel format, seq) to encode its messages too); returns its handle."""
        handle = self._next
        self._next += 1
        req = (spans, t_start, frame, exposure_us, encode)
        if self.local:
            self._done[handle] = _render(self.emu, req)
        else:
            self._sent.append((handle, req))
            sp = np.ascontiguousarray(spans, np.int32)
            self._send(bytes((_RENDER,)) + _REQ.pack(handle, t_start, frame, exposure_us, len(sp), encode is not None)
                       + sp.tobytes() + (_pack_encode(encode) if encode is not None else b""))
        return handle

    def result(self, handle: int) -> tuple:
        """``(pixels, FRAME messages or None)`` of render ``handle`` (waits for the child)."""
        while handle not in self._done:
            if self.local or not self._sent:
                raise KeyError(f"render {handle} was never submitted or was discarded")
            w0 = time.perf_counter()
            try:
                msg = self._conn.recv_bytes()
            except (EOFError, OSError) as exc:
                self._fail(exc)
                continue
            finally:
                self.wait_s += time.perf_counter() - w0
            got, n = _ANS.unpack_from(msg)
            end = _ANS.size + 2 * n
            pixels = np.frombuffer(msg, np.uint16, n, _ANS.size).copy()
            answer = (pixels, pickle.loads(msg[end:]) if len(msg) > end else None)
            want, _ = self._sent.popleft()
            if got != want:
                self._fail(RuntimeError(f"answer {got} for render {want}"))
                continue
            if got in self._dropped:
                self._dropped.discard(got)
            else:
                self._done[got] = answer
        return self._done.pop(handle)

    def discard(self, handle: int) -> None:
        """Render ``handle`` will not be asked for."""
        if self._done.pop(handle, None) is None:
            self._dropped.add(handle)

    def eclipse(self, on: bool, exposure_us: int) -> None:
        self._send(bytes((_ECLIPSE,)) + _ECL.pack(bool(on), int(exposure_us)))

    def origin(self, t0: float) -> None:
        self._send(bytes((_ORIGIN,)) + _ORG.pack(float(t0)))

    # -- life ------------------------------------------------------------------------------
    def _send(self, msg) -> None:
        if self.local:
            return
        try:
            self._conn.send_bytes(msg)
        except (OSError, ValueError) as exc:
            self._fail(exc)

    def _fail(self, exc) -> None:
        """The child has gone: render what it owed here, in order, and all later renders."""
        if not self.local:
            self.failed = f"{type(exc).__name__}: {exc}" if str(exc) else type(exc).__name__
            log.warning("head render process ended (%s): rendering in the loop's process from frame %d on",
                        self.failed, self._sent[0][1][2] if self._sent else -1)
        self.local = True
        while self._sent:
            handle, req = self._sent.popleft()
            if handle in self._dropped:
                self._dropped.discard(handle)
            else:
                self._done[handle] = _render(self.emu, req)

    def close(self) -> None:
        if self._proc is None:
            return
        if not self.local:
            try:
                self._conn.send_bytes(bytes((_STOP,)))
            except (OSError, ValueError):
                pass
        self._proc.join(timeout=2.0)
        if self._proc.is_alive():
            self._proc.kill()
            self._proc.join(timeout=2.0)
        self._conn.close()
        self._proc = None
