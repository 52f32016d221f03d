"""The ``gyrostar`` console script: :func:`gyrostar.cli.main.main`, then a quick exit.

A run leaves numba's compiled libraries, the star catalogs and the run's arrays in memory;
the interpreter's teardown frees them one by one (about 0.2 s after a flatsat run). Once
every exit handler has run — the log handlers flushed, child processes joined, temporary
folders removed, every thread joined — there is nothing left to write, so the process
leaves there: standard output and error are flushed and the exit code is the command's.

This module imports only ``atexit``, ``os`` and ``sys`` before it registers its handler: exit
handlers run last-registered first, so it runs after those of every module the command
imports (logging, multiprocessing, numba, dask).
"""

import atexit
import os
import sys

_exit_code: list[int] = []


def _leave() -> None:
    """Last exit handler: flush standard output and error, then end the process with the
    command's exit code (only when :func:`console` set one)."""
    if not _exit_code:
        return
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):   # a reader that went away, a stream already closed
            pass
    os._exit(_exit_code[0])


atexit.register(_leave)


def console() -> None:
    """Entry point of the ``gyrostar`` script and of ``python -m gyrostar``."""
    from .main import main

    code = int(main() or 0)
    _exit_code.append(code)
    sys.exit(code)
