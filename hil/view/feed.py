"""The live view beside a run: options, the view process and the bounded hand-over to it.

The view rides on the log: the run's :class:`~gyrostar.recording.logfile.LogWriter` hands each
run of whole records it drains (every ``flush_s`` = 50 ms, on its writer thread, off the 400 Hz
path) to :meth:`ViewFeed.tee`, which only queues the bytes (a bounded queue of
:data:`QUEUE_CHUNKS` runs). A feeder thread writes them into a pipe to the view process
(``python -m gyrostar.hil.view.worker``, niced; in real time on SCHED_IDLE), where they are
decoded and drawn with rerun.
In real time a full queue drops the run of records for the view (counted, the log has them
all); a fast run (simulated clock) waits for the view instead, so its recording is complete.
``--view-serve`` starts rerun's own server (``rerun --serve-web --bind 127.0.0.1``): the web
viewer and its data port on loopback only.
"""

from __future__ import annotations

import json
import logging
import os
import queue
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import crc32c

from ...errors import ConfigError, NotAvailableError
from ...recording import logfile as lf
from .worker import LEN

log = logging.getLogger(__name__)
QUEUE_CHUNKS = 64            # runs of records waiting for the view (~3 s of a run at 50 ms each)
DEFAULT_WEB_PORT = 9090      # rerun's web viewer port
SERVER_START_S = 20.0        # the rerun server must listen within this (s)
CLOSE_TIMEOUT_S = 600.0      # the view process must have drawn everything within this after the run (s)
NO_RERUN = "--view needs rerun-sdk, not installed here: pip install 'gyrostar[view]'"


@dataclass
class ViewOptions:
    """``--view`` (a native viewer), ``--view-save FILE.rrd``, ``--view-serve [PORT]`` (web viewer)."""

    spawn: bool = False
    save: str | None = None
    serve: int | None = None

    @property
    def wanted(self) -> bool:
        return bool(self.spawn or self.save or self.serve is not None)

    def describe(self) -> str:
        parts = (["native viewer"] if self.spawn else []) + ([f"recording {self.save}"] if self.save else []) \
            + ([f"web viewer on 127.0.0.1:{self.serve}"] if self.serve is not None else [])
        return ", ".join(parts)


def options_from(args) -> ViewOptions | None:
    """The view options of a parsed ``run``/``replay`` command line (None: no view)."""
    opts = ViewOptions(bool(getattr(args, "view", False)), getattr(args, "view_save", None),
                       getattr(args, "view_serve", None))
    return opts if opts.wanted else None


def check(opts: ViewOptions) -> None:
    """Refuse what cannot work before anything runs: rerun-sdk missing or no display (exit 4),
    a recording path that exists or has no folder (exit 2)."""
    try:
        import rerun  # noqa: F401 - only whether it imports (the drawing is in the view process)
    except ImportError:
        raise NotAvailableError(NO_RERUN) from None
    if opts.spawn and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        raise NotAvailableError("--view opens rerun's native viewer, which needs a display (DISPLAY and "
                                "WAYLAND_DISPLAY are unset): use --view-serve or --view-save")
    if opts.save:
        path = Path(opts.save)
        if path.exists():
            raise ConfigError(f"--view-save {path}: the file exists; choose another")
        if not path.parent.is_dir():
            raise ConfigError(f"--view-save {path}: folder {path.parent} does not exist")
    if opts.serve is not None and _rerun_binary() is None:
        raise NotAvailableError("--view-serve needs rerun-sdk's 'rerun' program beside this Python: not found")


def record_bytes(kind: int, payload: bytes, channel: int = 0, t_ns: int = 0) -> bytes:
    """One log record as the log file holds it (the view reads the same layout)."""
    head = lf.HEADER.pack(lf.SYNC, kind, channel, len(payload), int(t_ns))
    return head + payload + lf.CRC.pack(crc32c.crc32c(payload, crc32c.crc32c(head)))


def _rerun_binary() -> str | None:
    return shutil.which("rerun", path=os.path.dirname(sys.executable)) or shutil.which("rerun")


def _last_line(f) -> str:
    """The last non-empty line of a child's captured stderr (a temporary file)."""
    if f is None:
        return ""
    f.seek(0)
    lines = [x for x in f.read().decode(errors="replace").splitlines() if x.strip()]
    return lines[-1][-300:] if lines else "no message"


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class ViewServer:
    """rerun's web viewer and data proxy on loopback (``rerun --serve-web --bind 127.0.0.1``)."""

    def __init__(self, web_port: int):
        self.web_port = web_port
        self.grpc_port = free_port()
        self.proc: subprocess.Popen | None = None
        self._err = None

    @property
    def proxy_url(self) -> str:
        return f"rerun+http://127.0.0.1:{self.grpc_port}/proxy"

    @property
    def viewer_url(self) -> str:
        from urllib.parse import quote

        return f"http://127.0.0.1:{self.web_port}/?url={quote(self.proxy_url, safe='')}"

    def start(self) -> ViewServer:
        from ...cli.interrupt import release_held_signals, signals_held

        self._err = tempfile.TemporaryFile()
        with signals_held():
            self.proc = subprocess.Popen(
                [_rerun_binary(), "--serve-web", "--bind", "127.0.0.1", "--port", str(self.grpc_port),
                 "--web-viewer-port", str(self.web_port), "--server-memory-limit", "25%"],
                stdin=subprocess.DEVNULL, stdout=self._err, stderr=self._err, start_new_session=True,
                preexec_fn=release_held_signals)
        deadline = time.monotonic() + SERVER_START_S
        while time.monotonic() < deadline:
            if self.proc.poll() is not None:
                raise NotAvailableError(f"--view-serve: rerun's server ended at start ({_last_line(self._err)})")
            try:
                with socket.create_connection(("127.0.0.1", self.grpc_port), timeout=0.2), \
                        socket.create_connection(("127.0.0.1", self.web_port), timeout=0.2):
                    return self
            except OSError:
                time.sleep(0.1)
        self.close()
        raise NotAvailableError(f"--view-serve: rerun's server did not listen on 127.0.0.1:{self.web_port} "
                                f"within {SERVER_START_S:.0f} s (port taken?)")

    def wait(self) -> None:
        """Serve until Ctrl-C (or SIGTERM), or until the server ends."""
        while self.proc is not None and self.proc.poll() is None:
            time.sleep(0.2)

    def close(self) -> None:
        """Stop the server: its whole process group (the ``rerun`` launcher runs the server binary
        as its child, which a signal to the launcher alone would leave running)."""
        if self.proc is not None:
            for sig in (signal.SIGTERM, signal.SIGKILL):
                try:
                    os.killpg(self.proc.pid, sig)
                except ProcessLookupError:
                    break
                if self._group_gone(5.0):
                    break
            self.proc.wait()
        self.proc = None

    def _group_gone(self, timeout: float) -> bool:
        """Whether every process of the server's group has ended within ``timeout`` (s)."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            self.proc.poll()         # reap the launcher when it ends
            try:
                os.killpg(self.proc.pid, 0)
            except ProcessLookupError:
                return True
            time.sleep(0.05)
        return False


class ViewFeed:
    """The view process of one run or replay, fed through a bounded queue (see the module doc).

    ``lossless``: wait for the view when the queue is full (fast runs, replays) instead of
    dropping the run of records. Counters: ``chunks``/``bytes`` queued, ``dropped_chunks``/
    ``dropped_bytes`` (real time under load)."""

    def __init__(self, opts: ViewOptions, lossless: bool = False, recording_id: str | None = None):
        self.opts = opts
        self.lossless = lossless
        self.recording_id = recording_id
        self.server: ViewServer | None = None
        self.proc: subprocess.Popen | None = None
        self._q: queue.Queue = queue.Queue(maxsize=QUEUE_CHUNKS)
        self._thread: threading.Thread | None = None
        self._err = None
        self.chunks = self.bytes = self.dropped_chunks = self.dropped_bytes = 0
        self.failed: str | None = None

    def start(self) -> ViewFeed:
        from ...cli.interrupt import release_held_signals, signals_held

        check(self.opts)
        if self.opts.serve is not None:
            self.server = ViewServer(self.opts.serve).start()
        cmd = [sys.executable, "-m", "gyrostar.hil.view.worker"]
        if self.opts.save:
            cmd += ["--save", str(self.opts.save)]
        if self.server is not None:
            cmd += ["--connect", self.server.proxy_url]
        if self.opts.spawn:
            cmd += ["--spawn"]
        if self.recording_id:
            cmd += ["--recording-id", self.recording_id]
        if not self.lossless:
            cmd += ["--idle"]        # real time: the view takes only CPU time the loop leaves
        self._err = tempfile.TemporaryFile()     # a view that says much can never block on a pipe
        env = dict(os.environ, RERUN_ANALYTICS="0")
        with signals_held():
            self.proc = subprocess.Popen(cmd, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=self._err,
                                         start_new_session=True, env=env, preexec_fn=release_held_signals)
        self._thread = threading.Thread(target=self._feed, name="view-feed", daemon=True)
        self._thread.start()
        return self

    def send_records(self, records) -> None:
        """Queue log records (:class:`~gyrostar.recording.logfile.Record`) in runs of ~64 kB
        (a replay, or the run's META before the writer's tee takes over)."""
        buf = bytearray()
        for r in records:
            buf += record_bytes(r.kind, r.payload, r.channel, r.t_ns)
            if len(buf) >= 1 << 16:
                self.tee(bytes(buf))
                buf = bytearray()
        if buf:
            self.tee(bytes(buf))

    def tee(self, data) -> None:
        """A run of whole records for the view: queued, never waited for in real time."""
        if self.failed is not None:
            return
        try:
            if self.lossless:
                self._q.put(data)
            else:
                self._q.put_nowait(data)
            self.chunks += 1
            self.bytes += len(data)
        except queue.Full:
            self.dropped_chunks += 1
            self.dropped_bytes += len(data)

    def _feed(self) -> None:
        pipe = self.proc.stdin
        while True:
            data = self._q.get()
            if data is None:
                break
            try:
                pipe.write(LEN.pack(len(data)))
                pipe.write(data)
            except (BrokenPipeError, OSError) as exc:
                self.failed = f"the view process stopped reading ({exc.strerror or exc})"
                break
        try:
            if self.failed is None:
                pipe.write(LEN.pack(0))
            pipe.close()
        except OSError:
            pass

    def close(self, timeout: float = CLOSE_TIMEOUT_S) -> dict:
        """Hand over what is queued, let the view finish drawing, and return its figures."""
        if self.proc is None:
            return {}
        self._q.put(None)
        self._thread.join(timeout)
        self.proc.stdin = None         # the feeder closed it
        try:
            out, _ = self.proc.communicate(timeout=timeout)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            out, _ = self.proc.communicate()
            self.failed = self.failed or f"the view process did not finish within {timeout:.0f} s"
        drawn = {}
        try:
            drawn = json.loads(out.decode().strip().splitlines()[-1]) if out.strip() else {}
        except (ValueError, IndexError):
            pass
        if self.proc.returncode != 0 and self.failed is None:
            self.failed = f"the view process failed (exit {self.proc.returncode}: {_last_line(self._err)})"
        self.proc = None
        res = {"shown": self.opts.describe(), "chunks": self.chunks, "bytes": self.bytes,
               "dropped_chunks": self.dropped_chunks, "dropped_bytes": self.dropped_bytes,
               "frames": drawn.get("frames"), "records": drawn.get("records")}
        if self.opts.save:
            res["recording"] = str(self.opts.save)
        if self.server is not None:
            res["web_viewer"] = self.server.viewer_url
        if self.failed:
            res["error"] = self.failed
            log.warning("view: %s", self.failed)
        return res


    def serve_until_interrupted(self) -> bool:
        """``--view-serve``: keep the web viewer up after the run until Ctrl-C; True if it served."""
        if self.server is None:
            return False
        log.warning("view: web viewer at %s — serving until Ctrl-C", self.server.viewer_url)
        try:
            self.server.wait()
        except KeyboardInterrupt:
            pass
        finally:
            self.server.close()
        return True

    def abort(self) -> None:
        """Stop the view process and server at once (a failed start)."""
        if self.proc is not None and self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait()
        self.proc = None
        if self.server is not None:
            self.server.close()
