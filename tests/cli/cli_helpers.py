"""Shared helpers of the CLI tests: run the real console script as a subprocess."""

import contextlib
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


@contextlib.contextmanager
def tmpfs(path: Path, options: str, why: str):
    """A tmpfs mounted at ``path`` (made) with ``options`` ("size=1m", "ro,size=1m") while the
    block runs; the test is skipped (``why``) where it cannot be mounted (not root)."""
    path.mkdir(parents=True, exist_ok=True)
    if subprocess.run(["mount", "-t", "tmpfs", "-o", options, "tmpfs", str(path)], capture_output=True).returncode:
        pytest.skip(why)
    try:
        yield path
    finally:
        subprocess.run(["umount", str(path)], check=True)
