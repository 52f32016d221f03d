"""Shared pytest fixtures and paths."""

from pathlib import Path

import gyrostar  # noqa: F401  (imported first: pins BLAS to one thread before numpy loads)
import pytest

REPO = Path(__file__).resolve().parent.parent


@pytest.fixture
def repo() -> Path:
    return REPO


@pytest.fixture
def ctrl_c_raises():
    """SIGINT raises KeyboardInterrupt in this test, as in a terminal: a test session started
    in the background by a non-interactive shell inherits SIGINT ignored (POSIX), and Python
    then leaves it ignored."""
    import signal

    old = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, old)


@pytest.fixture
def wait_signal_held():
    """A function that waits (up to 5 s) until the SignalHold now handling SIGINT has recorded
    a signal: the kernel's delivery to another thread and Python's handler in the main thread
    take their time on a loaded machine, and a signal still pending when the hold ends would
    land outside the test's expectation (and stop the whole session)."""
    import signal
    import time

    def wait(timeout_s: float = 5.0) -> bool:
        hold = getattr(signal.getsignal(signal.SIGINT), "__self__", None)
        deadline = time.monotonic() + timeout_s
        while hold is not None and not hold.held and time.monotonic() < deadline:
            time.sleep(0.001)           # the main thread's sleep lets Python run the handler
        return hold is not None and bool(hold.held)

    return wait
