"""One run at a time in a run folder: an advisory lock on ``<folder>/.run.lock``.

``gyrostar run`` takes the lock (``flock``, exclusive, not waiting) before it looks at the
folder's contents, and holds it until the command ends: a second run given the same
``--out`` while the first is running is refused with one line naming the folder and the
process that holds it, and nothing of the first run (its open log, ``summary.json``,
figures) is renamed or overwritten. The kernel drops the lock when the holder ends, however
it ends (a crash or ``kill -9`` included), so a stale lock file never blocks a later run;
the file itself stays (it holds the last holder's process id).
"""

from __future__ import annotations

import fcntl
import os
from pathlib import Path

from ..errors import ConfigError

LOCK_NAME = ".run.lock"


class RunFolderLock:
    """The held lock of one run folder; released by :meth:`release` or when dropped."""

    def __init__(self, folder: Path, fd: int):
        self.folder = folder
        self._fd = fd

    @property
    def held(self) -> bool:
        return self._fd is not None

    def release(self) -> None:
        if self._fd is not None:
            fd, self._fd = self._fd, None
            os.close(fd)        # closing the descriptor drops the flock

    def __enter__(self) -> RunFolderLock:
        return self

    def __exit__(self, *exc) -> None:
        self.release()

    def __del__(self) -> None:
        self.release()


def lock_run_folder(folder: Path, what: str = "--out") -> RunFolderLock:
    """Take ``folder``'s run lock, or raise :class:`ConfigError` (exit 2) naming ``what`` and
    the folder when another run holds it or the lock cannot be taken."""
    folder = Path(folder)
    path = folder / LOCK_NAME
    try:
        fd = os.open(path, os.O_RDWR | os.O_CREAT | getattr(os, "O_CLOEXEC", 0), 0o644)
    except OSError as exc:
        raise ConfigError(f"{what} {folder}: cannot create its lock file {LOCK_NAME}: {exc.strerror or exc}") from None
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        holder = _holder(fd)
        os.close(fd)
        raise ConfigError(f"{what} {folder} is in use by another run{holder}: wait for it to end or choose "
                          "another --out") from None
    except OSError as exc:
        os.close(fd)
        raise ConfigError(f"{what} {folder}: cannot lock it for this run ({exc.strerror or exc})") from None
    try:
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
    except OSError:
        pass        # the lock holds without the process id (only the refusal's message lacks it)
    return RunFolderLock(folder, fd)


def _holder(fd: int) -> str:
    """`` (process N)`` from the lock file, "" when it does not say."""
    try:
        pid = int(os.pread(fd, 32, 0).split()[0])
    except (OSError, ValueError, IndexError):
        return ""
    return f" (process {pid})"
