"""SIGTERM handled like Ctrl-C while a firmware tool runs a child program.

Python's default SIGTERM action ends the process at once: no ``finally`` runs, so a child
started with :mod:`subprocess` (the firmware host program, QEMU) outlives a launcher that a
service manager or ``kill`` stopped. Inside :func:`sigterm_as_interrupt` SIGTERM raises
:class:`Terminated` (a ``KeyboardInterrupt``), so the same clean-up paths run as for Ctrl-C
and the CLI reports "interrupted" with exit code 130.
"""

from __future__ import annotations

import signal
import subprocess
import threading
from contextlib import contextmanager


class Terminated(KeyboardInterrupt):
    """SIGTERM arrived."""


def _raise_terminated(signum, frame):
    raise Terminated(f"signal {signum}")


@contextmanager
def sigterm_as_interrupt():
    """SIGTERM raises :class:`Terminated` in the main thread until the block ends (no-op in
    other threads, where Python cannot install handlers)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    old = signal.signal(signal.SIGTERM, _raise_terminated)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, old)


def stop_child(proc: subprocess.Popen, grace_s: float = 2.0) -> None:
    """SIGTERM the child, give it ``grace_s`` to clean up (unlink its pty link), then SIGKILL;
    always reaped."""
    if proc.poll() is None:
        proc.terminate()
        try:
            proc.wait(timeout=grace_s)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
