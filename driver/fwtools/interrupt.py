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

from ..cli.interrupt import SignalHold


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


_HELD = {signal.SIGINT, signal.SIGTERM}


@contextmanager
def signals_held():
    """Hold SIGINT and SIGTERM back while the block runs (delivered when it ends): wrap the
    start of a child so that a signal cannot arrive before the handle to stop it exists. The
    child inherits the mask: give it :func:`release_held_signals` as ``preexec_fn``.

    The mask holds only this thread's share: the kernel gives a process-directed signal to any
    thread that does not block it, and Python then runs the handler in the main thread at once.
    So on the main thread a :class:`gyrostar.cli.interrupt.SignalHold` records them meanwhile
    and raises a held one when the block ends."""
    hold = SignalHold()
    old = signal.pthread_sigmask(signal.SIG_BLOCK, _HELD)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)     # a signal pending on us: to the hold now
        hold.release()


def release_held_signals() -> None:
    """In a forked child before exec: SIGINT and SIGTERM reach it again."""
    signal.pthread_sigmask(signal.SIG_UNBLOCK, _HELD)


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
