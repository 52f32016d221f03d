"""Ctrl-C and SIGTERM for the console script: remember that one arrived.

:func:`watch` installs a SIGINT and a SIGTERM handler that record the signal and raise
:class:`KeyboardInterrupt` as Python's default SIGINT handler does, so ``kill PID`` (a service
manager stopping the run) ends a run as Ctrl-C does: one line, the summary and plots of the
part that ran, exit 130. A Ctrl-C that lands inside native code
(numba's cache loader, a C extension calling back into Python) can surface as another
exception (``SystemError``, ``EOFError``...); :func:`seen` lets the CLI still report it as an
interruption (exit 130) rather than a crash. Child processes the driver forks ignore SIGINT
(:func:`ignore_in_child`): the parent stops them, so a terminal's Ctrl-C, which reaches the
whole process group, never leaves a traceback from a child.
"""

from __future__ import annotations

import signal
import threading
from contextlib import contextmanager

_seen = threading.Event()
_signal_name = ["SIGINT"]


def _handler(signum, frame):
    _signal_name[0] = signal.Signals(signum).name
    _seen.set()
    raise KeyboardInterrupt


def seen() -> bool:
    """True once SIGINT or SIGTERM has arrived under :func:`watch`."""
    return _seen.is_set()


def reason() -> str:
    """``"interrupted"`` for Ctrl-C, ``"terminated (SIGTERM)"`` for SIGTERM."""
    return "terminated (SIGTERM)" if _seen.is_set() and _signal_name[0] == "SIGTERM" else "interrupted"


@contextmanager
def watch():
    """Record SIGINT and SIGTERM while the block runs (main thread only; elsewhere a no-op)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    _seen.clear()
    _signal_name[0] = "SIGINT"
    old_int = signal.signal(signal.SIGINT, _handler)
    old_term = signal.signal(signal.SIGTERM, _handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, old_int)
        signal.signal(signal.SIGTERM, old_term)


@contextmanager
def sigint_blocked():
    """Hold SIGINT back (delivered when the block ends): wrap a fork so the child can set
    :func:`ignore_in_child` before any Ctrl-C reaches it."""
    old = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


def ignore_in_child() -> None:
    """In a forked child: ignore SIGINT (the parent stops us), then unblock it."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})
