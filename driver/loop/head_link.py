"""The head link as the loop sees it: up, or down since when; jobs unanswered in a row;
when to try to reconnect.

The loop declares the link lost on a :class:`gyrostar.errors.LinkLostError`, on a failed
full frame or when ``timeouts_lost`` head jobs in a row went unanswered
(:meth:`HeadLink.job_failed`); while it is down the loop coasts and asks the head port to
reconnect every ``reconnect_every_s`` (:meth:`HeadLink.reconnect_due`) until a reconnect
succeeds (:meth:`HeadLink.back`). Times are host seconds on the loop's clock; no clock is
read here.
"""

from __future__ import annotations

import math


class HeadLink:
    def __init__(self, reconnect_every_s: float, timeouts_lost: int):
        self.reconnect_every_s = float(reconnect_every_s)
        self.timeouts_lost = int(timeouts_lost)
        self.down_since: float | None = None    # host s the link went down (None: up)
        self.timeouts = 0                       # head jobs in a row without an answer
        self.next_reconnect_t = -math.inf       # host s of the next reconnection attempt

    @property
    def up(self) -> bool:
        return self.down_since is None

    def lost(self, now: float) -> None:
        """The link went down at ``now`` (s), when it was up: the first attempt to reconnect
        is one ``reconnect_every_s`` later."""
        if self.down_since is None:
            self.down_since = now
            self.next_reconnect_t = now + self.reconnect_every_s

    def back(self, now: float) -> float:
        """A reconnect succeeded at ``now``: the link is up; returns how long it was down (s)."""
        down = now - self.down_since if self.down_since is not None else 0.0
        self.down_since = None
        self.timeouts = 0
        return down

    def answered(self) -> None:
        """A head job was answered: the count of unanswered ones restarts."""
        self.timeouts = 0

    def job_failed(self, timeout: bool) -> bool:
        """A head job failed (``timeout``: no answer; else an answer that was an error).
        Returns whether that makes ``timeouts_lost`` unanswered jobs in a row."""
        self.timeouts = self.timeouts + 1 if timeout else 0
        return self.timeouts >= self.timeouts_lost

    def reconnect_due(self, now: float, busy: bool) -> bool:
        """Whether to ask for a reconnect at ``now`` (the port not ``busy`` with a job); if so
        the next attempt is one ``reconnect_every_s`` later."""
        if busy or now < self.next_reconnect_t:
            return False
        self.next_reconnect_t = now + self.reconnect_every_s
        return True
