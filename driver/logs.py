"""Logging set-up for the CLI: one stdlib logger per module, level from -v/-q.

On a terminal the records go through rich; otherwise (a pipe, a file, a test capturing
stderr) each record is one plain line, never wrapped at the console width.
"""

import logging
import sys
import time
from contextlib import contextmanager

# what a user waits for (compiling the kernels, building the star index), shown by default, not with -q
NOTICE = 25
logging.addLevelName(NOTICE, "NOTE")


@contextmanager
def stage(what: str, told: bool = True):
    """A NOTICE line before a stage a user waits for (``what``: "building the star index …") when
    ``told``, and its time after it."""
    log = logging.getLogger("gyrostar")
    if told:
        log.log(NOTICE, "%s", what)
    t0 = time.perf_counter()
    yield
    if told:
        log.log(NOTICE, "done in %.0f s: %s", time.perf_counter() - t0, what.split(":")[0].split(" (")[0])


def setup(verbosity: int) -> None:
    """verbosity: -1 quiet (errors), 0 notices and warnings, 1 info, 2+ debug. Logs go to stderr."""
    level = {-1: logging.ERROR, 0: NOTICE, 1: logging.INFO}.get(verbosity, logging.DEBUG)
    if sys.stderr.isatty():
        from rich.console import Console
        from rich.logging import RichHandler

        handler = RichHandler(console=Console(stderr=True, soft_wrap=True), show_path=False, show_time=False)
        fmt = "%(name)s: %(message)s"
    else:
        handler = logging.StreamHandler(sys.stderr)
        fmt = "%(name)s: %(levelname)s: %(message)s"
    handler.setFormatter(logging.Formatter(fmt))
    logging.basicConfig(level=level, handlers=[handler], force=True)
    # numba's compiler logs every bytecode it reads at DEBUG: nothing a user of -vv looks for
    logging.getLogger("numba").setLevel(max(level, logging.WARNING))
