"""Shared helpers of the CLI tests: run the real console script as a subprocess."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

GYROSTAR = str(Path(sys.executable).parent / "gyrostar")


def gyrostar(args, cwd=None, env=None, timeout=120) -> subprocess.CompletedProcess:
    """``gyrostar ARGS`` in a subprocess (stdin closed, stderr not a terminal)."""
    e = dict(os.environ)
    e.update(env or {})
    return subprocess.run([GYROSTAR, *[str(a) for a in args]], capture_output=True, text=True, cwd=cwd, env=e,
                          timeout=timeout, stdin=subprocess.DEVNULL)


@pytest.fixture
def runs(tmp_path, monkeypatch) -> Path:
    """A fresh ``$GYROSTAR_RUNS`` for the test."""
    path = tmp_path / "runs"
    monkeypatch.setenv("GYROSTAR_RUNS", str(path))
    return path
