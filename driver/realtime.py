"""Real-time priorities of the driver's threads (Linux SCHED_FIFO, when permitted).

The loop thread asks for SCHED_FIFO at ``priority`` (:func:`gyrostar.loop.scheduler.realtime_setup`,
which records it here). Threads and processes it starts afterwards are reset to SCHED_OTHER
(``SCHED_RESET_ON_FORK``): device emulators and other host work never compete with it.
The driver's own worker threads (head-link reader, head port, spot measuring) share the
interpreter lock with the loop, so one of them preempted by the host while holding that
lock would stall the loop (priority inversion): each calls :func:`join_realtime` when it
starts and runs SCHED_FIFO one level below the loop.
"""

from __future__ import annotations

import os

_loop_priority = 0


def set_loop_priority(priority: int) -> None:
    """Record the loop thread's granted SCHED_FIFO priority (0: not real-time)."""
    global _loop_priority
    _loop_priority = int(priority)


def loop_priority() -> int:
    return _loop_priority


def fifo_policy() -> int:
    """SCHED_FIFO with reset-on-fork where the platform has it."""
    return os.SCHED_FIFO | getattr(os, "SCHED_RESET_ON_FORK", 0)


def join_realtime(below: int = 1) -> bool:
    """Run the calling thread SCHED_FIFO at the loop's priority − ``below`` (if the loop is
    real-time and the host permits it); returns whether it was granted."""
    prio = _loop_priority - below
    if _loop_priority <= 0 or prio < 1:
        return False
    try:
        os.sched_setscheduler(0, fifo_policy(), os.sched_param(prio))
    except (OSError, AttributeError):
        return False
    return True


def leave_realtime() -> None:
    """Back to SCHED_OTHER for the calling (loop) thread; workers started later stay normal."""
    set_loop_priority(0)
    try:
        if os.sched_getscheduler(0) & ~getattr(os, "SCHED_RESET_ON_FORK", 0) != os.SCHED_OTHER:
            os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
    except (OSError, AttributeError):
        pass
