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


def warm(calls) -> dict:
    """Run each ``(fn, args)`` once; returns {"seconds", "functions", "cache_hits", "compiled"}."""
    t0 = time.perf_counter()
    hits = compiled = 0
    for fn, args in calls:
        before = _hits(fn)
        fn(*args)
        after = _hits(fn)
        if after > before:
            hits += 1
        else:
            compiled += 1
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
