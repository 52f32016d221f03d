"""Ctrl-C and SIGTERM for the console script: remember that one arrived.

:func:`watch` installs a SIGINT and a SIGTERM handler that record the signal and raise
:class:`KeyboardInterrupt` as Python's default SIGINT handler does, so ``kill PID`` (a service
manager stopping the run) ends a run as Ctrl-C does: one line, the summary and plots of the
part that ran, exit 130. A Ctrl-C that lands inside native code
(numba's cache loader, a C extension calling back into Python) can surface as another
exception (``SystemError``, ``EOFError``...); :func:`seen` lets the CLI still report it as an
interruption (exit 130) rather than a crash. Child processes the driver forks ignore SIGINT
and take SIGTERM's default action (:func:`ignore_in_child`): the parent stops them, so a
terminal's Ctrl-C or a service manager's SIGTERM, which reach the whole process group, never
leave a traceback from a child.
"""

from __future__ import annotations

import signal
import sys
import threading
from contextlib import contextmanager

_seen = threading.Event()
_signal_name = ["SIGINT"]


def _handler(signum, frame):
    _signal_name[0] = signal.Signals(signum).name
    _seen.set()
    raise KeyboardInterrupt


def raise_if_seen() -> None:
    """Raise :class:`KeyboardInterrupt` when a signal arrived under :func:`watch` whose
    exception was swallowed (Python drops an exception raised in a weakref or ``__del__``
    callback, e.g. an import lock's, and only prints it): call where a run may stop cleanly."""
    if _seen.is_set():
        raise KeyboardInterrupt


def _quiet_unraisable(hook):
    """``sys.unraisablehook`` that drops the KeyboardInterrupt of a signal seen under
    :func:`watch` (it ends the run at the next :func:`raise_if_seen`) and passes the rest on."""

    def quiet(unraisable):
        if _seen.is_set() and isinstance(unraisable.exc_value, KeyboardInterrupt):
            return
        hook(unraisable)

    return quiet


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
    old_hook = sys.unraisablehook
    sys.unraisablehook = _quiet_unraisable(old_hook)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, old_int)
        signal.signal(signal.SIGTERM, old_term)
        sys.unraisablehook = old_hook


class SignalHold:
    """SIGINT and SIGTERM held from construction to :meth:`release`: Python-level handlers
    record them, and ``release`` puts the handlers found before back and raises a held signal
    through them (so it lands where the caller releases, e.g. inside a ``try`` that records it).
    A signal mask alone would not do: the kernel gives a process-directed signal to any thread
    that does not block it, and Python then runs the handler in the main thread at once, inside
    the region that was to hold it. Main thread only (where Python runs handlers); elsewhere a
    no-op."""

    def __init__(self):
        self.held: list[int] = []
        self.prev: dict = {}
        if threading.current_thread() is threading.main_thread():
            for s in (signal.SIGINT, signal.SIGTERM):
                old = signal.signal(s, self._hold)
                self.prev[s] = signal.SIG_DFL if old is None else old

    def _hold(self, signum, frame):
        self.held.append(signum)

    def release(self) -> None:
        """Previous handlers back; a held signal raised now (once; later calls do nothing)."""
        prev, self.prev = self.prev, {}
        late = None
        for s, h in prev.items():
            while True:
                try:
                    signal.signal(s, h)
                    break
                except KeyboardInterrupt as exc:    # a signal came in meanwhile and its handler, put
                    late = exc                      # back, raised: put the rest back, then raise it
        if late is not None:
            raise late
        if prev and self.held:
            signal.raise_signal(self.held[0])


_HELD = {signal.SIGINT, signal.SIGTERM}


@contextmanager
def signals_held():
    """Hold SIGINT and SIGTERM back while the block runs (delivered when it ends): wrap the
    start of a child (a fork, a ``subprocess``) so that no signal arrives before the handle
    to stop it exists. The child inherits the mask: a forked Python child calls
    :func:`ignore_in_child`, an exec'd program gets :func:`release_held_signals` as
    ``preexec_fn``.

    The mask holds only this thread's share: the kernel gives a process-directed signal to any
    thread that does not block it, and Python then runs the handler in the main thread at once.
    So on the main thread a :class:`SignalHold` records them meanwhile and raises a held one
    when the block ends."""
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


def ignore_in_child() -> None:
    """In a forked child (started under :func:`signals_held`): ignore SIGINT (the parent stops
    us) and give SIGTERM its default action back, then unblock both. The parent's handlers,
    inherited through the fork, would raise KeyboardInterrupt and print a traceback when a
    terminal's Ctrl-C or a service manager's SIGTERM reaches the process group: the child
    ends at once on SIGTERM, quietly, and the parent stops the run as for Ctrl-C."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    release_held_signals()


class StepBoundary:
    """Ctrl-C and SIGTERM take effect between loop steps, never inside one.

    A step reads the gyro FIFO (logged as it is read) and then emits that batch's outputs
    (logged as they are emitted); a signal that raised between the two would leave a log whose
    last inputs have no outputs, and its replay would show one step more than the run did.
    Inside the block, a signal that arrives while :attr:`inside` is True is held and delivered
    (to the handler that was installed before: :func:`watch`'s or Python's default) by
    :meth:`step_done`; between steps it is delivered at once. Main thread only; elsewhere, or
    for a signal whose previous action is not a Python handler, nothing changes.
    """

    _SIGNALS = (signal.SIGINT, signal.SIGTERM)

    def __init__(self):
        self.inside = False
        self._pending: tuple | None = None
        self._old: dict = {}

    def __enter__(self) -> StepBoundary:
        raise_if_seen()
        if threading.current_thread() is threading.main_thread():
            for sig in self._SIGNALS:
                old = signal.getsignal(sig)
                if callable(old):
                    self._old[sig] = old
                    signal.signal(sig, self._on_signal)
        return self

    def __exit__(self, *exc) -> None:
        for sig, old in self._old.items():
            signal.signal(sig, old)
        self._old.clear()
        self.inside = False
        self._deliver()

    def _on_signal(self, signum, frame) -> None:
        if self.inside:
            self._pending = (signum, frame)
            return
        self._old[signum](signum, frame)

    def step_done(self) -> None:
        """The step ended: deliver a signal held during it (or one whose exception was
        swallowed: :func:`raise_if_seen`)."""
        self.inside = False
        self._deliver()
        raise_if_seen()

    def _deliver(self) -> None:
        if self._pending is not None:
            signum, frame = self._pending
            self._pending = None
            handler = self._old.get(signum) or signal.getsignal(signum)
            if callable(handler):
                handler(signum, frame)
            else:
                raise KeyboardInterrupt
