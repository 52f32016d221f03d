"""Input files read whole: regular files only, each read bounded by its format's limit.

A path a user gives (a config, scenario or calibration TOML, a flatsat log, a FITS map) may
name anything: a folder, a FIFO (whose ``open`` waits for a writer), or a character device
such as ``/dev/zero`` or ``/dev/urandom`` (endless). :func:`read_regular` opens without
waiting (``O_NONBLOCK``), refuses anything that is not a regular file with one
:class:`ConfigError` naming it, and reads at most the format's limit: never more than the
file's size when it was opened. :func:`check_regular` says the same from the path alone,
for readers that open the file themselves (astropy, numpy).
"""

from __future__ import annotations

import os
import stat
from contextlib import contextmanager
from pathlib import Path

from .errors import ConfigError

TOML_MAX_BYTES = 16 * 2**20     # a config, scenario or calibration TOML (a [dark] table's hot pixels included)
_CHUNK = 16 * 2**20


def kind_of(mode: int) -> str:
    """What a file of ``st_mode`` ``mode`` is, in words ("a FIFO", "a character device", …)."""
    for test, words in ((stat.S_ISDIR, "a folder"), (stat.S_ISFIFO, "a FIFO (named pipe)"),
                        (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"),
                        (stat.S_ISSOCK, "a socket")):
        if test(mode):
            return words
    return "not a regular file"


def _refuse_kind(path, what: str, mode: int, hint: str) -> ConfigError:
    return ConfigError(f"{what} {path} is {kind_of(mode)}, not a regular file{hint}")


def check_regular(path: str | Path, what: str, hint: str = "") -> os.stat_result:
    """``os.stat`` of ``path``; :class:`ConfigError` naming ``what`` when it is missing,
    unreadable or not a regular file (``hint`` is appended to that message)."""
    try:
        st = os.stat(path)
    except FileNotFoundError:
        raise ConfigError(f"{what} {path} does not exist") from None
    except OSError as exc:
        raise ConfigError(f"{what} {path} cannot be read: {exc.strerror or exc}") from None
    if not stat.S_ISREG(st.st_mode):
        raise _refuse_kind(path, what, st.st_mode, hint)
    return st


def read_regular(path: str | Path, what: str, max_bytes: int | None = TOML_MAX_BYTES, hint: str = "") -> bytes:
    """The bytes of the regular file ``path`` as it was when opened (a file still growing
    is read up to its size then). :class:`ConfigError` naming ``what`` when it is missing,
    unreadable, not a regular file (``hint`` appended), or larger than ``max_bytes`` (None:
    no limit but its size; the caller has checked that it fits in memory)."""
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
    except FileNotFoundError:
        raise ConfigError(f"{what} {path} does not exist") from None
    except OSError as exc:
        raise ConfigError(f"{what} {path} cannot be read: {exc.strerror or exc}") from None
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            raise _refuse_kind(path, what, st.st_mode, hint)
        size = st.st_size
        if max_bytes is not None and size > max_bytes:
            raise ConfigError(f"{what} {path} is {size:,} bytes: more than a {what} can be "
                              f"({max_bytes:,} bytes)")
        parts = []
        left = size
        while left > 0:
            part = os.read(fd, min(left, _CHUNK))
            if not part:        # cut shorter while being read
                break
            parts.append(part)
            left -= len(part)
        return b"".join(parts)
    except OSError as exc:
        raise ConfigError(f"{what} {path} cannot be read: {exc.strerror or exc}") from None
    finally:
        os.close(fd)


@contextmanager
def whole_or_nothing(out: str | Path):
    """A temporary path beside ``out`` (``.<name>.partial-<pid><suffix>``) to write a file to,
    renamed to ``out`` once it is whole: an interrupted or failed write (Ctrl-C, a full disk,
    an error) leaves no file at ``out`` that looks complete (no 0-byte summary or PNG), removes
    its partial file, and does not make the next write to ``out`` ask for --force."""
    out = Path(out)
    part = out.with_name(f".{out.name}.partial-{os.getpid()}{out.suffix}")
    try:
        yield part
        os.replace(part, out)
    finally:
        part.unlink(missing_ok=True)
