"""The CPUs this process may run on: whether a run's helper processes (a render process,
figure helpers) can work beside it or would only take the runner's own CPU."""

from __future__ import annotations

import os


def cpus() -> int:
    """CPUs in this process's affinity set (the machine's count where that is not known)."""
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return os.cpu_count() or 1
