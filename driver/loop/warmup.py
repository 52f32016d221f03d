"""Numba start-up: compile or load every hot function before the first sample, timed.

:func:`warm` calls each ``(function, args)`` once and reports the seconds it took and
whether numba's on-disk cache served it (``dispatcher.stats.cache_hits``). A cold start
(empty ``NUMBA_CACHE_DIR``) compiles everything; a cached start only loads.
:func:`measure_startup` runs a fresh interpreter twice on an empty cache folder to give
both figures.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time

# s: compiling every kernel of the loop with an empty cache on a 2-core host (docs/HARDWARE.md
# "The first run"); the first estimate, before the compiles so far give one
COLD_COMPILE_S = 80.0
COLD_START_S = 150.0      # s: a whole cold start, kernels and star index (``gyrostar run --fast --duration 5``)
NOTE_EVERY_S = 10.0       # s between progress lines while compiling
COMPILE_SEEN_S = 0.2      # s: a first call this long compiled (a cached kernel loads in milliseconds)


def warm(calls) -> dict:
    """Run each ``(fn, args)`` once; returns {"seconds", "functions", "cache_hits", "compiled"}.
    While kernels compile (an empty or outdated cache) a progress line with an estimate of the
    time left goes to the log at NOTICE (shown by default) every :data:`NOTE_EVERY_S`."""
    import logging

    from ..logs import NOTICE

    log = logging.getLogger("gyrostar")
    t0 = time.perf_counter()
    hits = compiled = 0
    noted = None
    for i, (fn, args) in enumerate(calls):
        before = _hits(fn)
        t_fn = time.perf_counter()
        fn(*args)
        after = _hits(fn)
        if after > before:
            hits += 1
            continue
        compiled += 1
        now = time.perf_counter()
        if noted is None and now - t_fn > COMPILE_SEEN_S:       # a real compile, not a kernel already in memory
            noted = now
            log.log(NOTICE, "compiling the numba kernels (an empty or outdated cache: once after installing or "
                    "updating gyrostar): about %.0f s on an idle 2-core host; cached in %s", COLD_COMPILE_S,
                    os.environ.get("NUMBA_CACHE_DIR", "numba's default folder"))
        elif noted is not None and now - noted >= NOTE_EVERY_S:
            noted = now
            left = (now - t0) / (i + 1) * (len(calls) - i - 1)
            log.log(NOTICE, "compiling the numba kernels: %d of %d in %.0f s, about %.0f s left",
                    i + 1, len(calls), now - t0, left)
    if noted is not None:
        log.log(NOTICE, "numba kernels compiled in %.0f s (%d compiled, %d from the cache)",
                time.perf_counter() - t0, compiled, hits)
    return {"seconds": time.perf_counter() - t0, "functions": len(calls), "cache_hits": hits,
            "compiled": compiled}


def _hits(fn) -> int:
    stats = getattr(fn, "stats", None)
    if stats is None:
        return 0
    return sum(getattr(stats, "cache_hits", {}).values())


_PROBE = ("import json, time; t0 = time.perf_counter(); from gyrostar.loop import coupled; "
          "w = coupled.warmup(); w['total_s'] = time.perf_counter() - t0; print(json.dumps(w))")


def measure_startup() -> dict:
    """Start-up seconds with an empty numba cache (cold) and then with it filled (cached)."""
    out = {}
    with tempfile.TemporaryDirectory() as cache:
        env = dict(os.environ, NUMBA_CACHE_DIR=cache)
        for label in ("cold", "cached"):
            proc = subprocess.run([sys.executable, "-c", _PROBE], env=env, capture_output=True, text=True,
                                  timeout=600)
            if proc.returncode != 0:
                out[label] = {"error": proc.stderr.strip().splitlines()[-1:]}
                continue
            out[label] = json.loads(proc.stdout.strip().splitlines()[-1])
    return out


cold_start = False         # this process started on a cold cache (note_cold_start): later stages say they compile


def cache_is_cold() -> bool:
    """numba's cache folder holds no compiled kernel yet (``*.nbi`` index files): the first run
    after an install or update compiles every kernel."""
    from pathlib import Path

    folder = os.environ.get("NUMBA_CACHE_DIR")
    return not folder or not any(Path(folder).rglob("*.nbi"))


def note_cold_start() -> None:
    """One NOTICE line before a run's start-up when the kernels must be compiled: what takes
    the time, how long, and that it happens once."""
    import logging

    from ..logs import NOTICE

    global cold_start
    cold_start = cache_is_cold()
    if cold_start:
        logging.getLogger("gyrostar").log(
            NOTICE, "first start with this gyrostar: compiling its numba kernels and, for a new catalog or camera, "
            "building the star index take about %.0f s on an idle 2-core host (once: later starts take about a second)",
            COLD_START_S)
