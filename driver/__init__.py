"""gyrostar — software of a gyro-coupled star tracker.

Sub-packages map onto the repository folders: ``gyrostar`` is ``driver/`` (flight code
that runs on the on-board computer), ``gyrostar.mocks`` is ``mocks/`` (simulator, device
emulators, fake transports) and ``gyrostar.hil`` is ``hil/`` (flatsat runner, scenarios,
record/replay). See docs/ARCHITECTURE.md.
"""

import os as _os

__version__ = "0.1.0"

# Single-threaded BLAS: gyrostar's matrices are tiny, and a BLAS worker pool next to a
# SCHED_FIFO loop thread pinned to one CPU can livelock (the FIFO thread spins waiting for
# a worker that can never run). Set before numpy is first imported; an explicit setting wins.
_os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")


def _numba_cache_dir() -> None:
    """Point numba's on-disk cache at a folder named after the sources compiled code uses.

    ``@njit(cache=True)`` revalidates a cached function against its own source file only: a
    changed kernel or constant it uses from another module leaves its cached machine code
    stale (after a ``git pull``, the old code would run). The cache therefore lives in
    ``$GYROSTAR_CACHE/numba/<hash of the modules that use numba and every package module they
    import, transitively>`` (default ``$XDG_CACHE_HOME/gyrostar``, ``~/.cache/gyrostar``;
    :mod:`gyrostar.kernel_sources`): the cache root of :func:`gyrostar.paths.cache_dir`;
    a change there starts a fresh cache (one cold compile), a change elsewhere (the command
    line, plots, the runner) keeps it; the newest four are kept. An explicit
    ``NUMBA_CACHE_DIR`` wins.
    """
    import shutil
    import sys
    from pathlib import Path

    from .kernel_sources import kernel_sources_key

    if _os.environ.get("NUMBA_CACHE_DIR"):
        return
    here = Path(__file__).resolve().parent
    roots = [("gyrostar", here)]
    for name in ("mocks", "hil"):                  # sub-packages inside (installed) or beside (editable)
        for cand in (here / name, here.parent / name):
            if cand.is_dir() and cand != here:
                roots.append((f"gyrostar.{name}", cand))
                break
    base = (Path(_os.environ["GYROSTAR_CACHE"]) if _os.environ.get("GYROSTAR_CACHE")
            else Path(_os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "gyrostar") / "numba"
    target = base / kernel_sources_key(roots)[:16]
    try:
        target.mkdir(parents=True, exist_ok=True)
        old = sorted((p for p in base.iterdir() if p.is_dir() and p != target), key=lambda p: p.stat().st_mtime)
        for p in old[:-3]:
            shutil.rmtree(p, ignore_errors=True)
        _os.utime(target)
    except OSError:
        return                                     # unwritable home: numba's default (beside the sources)
    _os.environ["NUMBA_CACHE_DIR"] = str(target)
    if "numba" in sys.modules:                     # imported before gyrostar: set its config too
        sys.modules["numba"].config.CACHE_DIR = str(target)


_numba_cache_dir()
