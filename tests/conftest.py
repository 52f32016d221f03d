"""Shared pytest fixtures and paths."""

from pathlib import Path

import gyrostar  # noqa: F401  (imported first: pins BLAS to one thread before numpy loads)
import pytest

REPO = Path(__file__).resolve().parent.parent


@pytest.fixture
def repo() -> Path:
    return REPO
