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
