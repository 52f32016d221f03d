"""Streaming head: the window plans commanded for its frames, by frame number.

The loop commands the windows of the frame two ahead of the newest one (while the next
one integrates) and keeps each plan until that frame's pixels come back, read with the set
the head installed for it (``set_frame``). Plans more than :data:`KEEP_FRAMES` frames
older than the newest commanded are dropped (their frames were lost or read with a later
set). A reconnect or a full frame restarts the stream: every plan goes, and the next set
commanded starts it again (frame 0), at most one every :data:`START_EVERY_S`.
"""

from __future__ import annotations

import math

KEEP_FRAMES = 8        # frames: plans this much older than the newest commanded are dropped
START_EVERY_S = 0.2    # s between sets sent to start a stream that has not started


class StreamPlans:
    def __init__(self) -> None:
        self.by_frame: dict = {}          # stream frame → its window plan
        self.last_commanded = 0           # newest frame whose windows were commanded
        self.start_wait = -math.inf       # host s before which no other starting set is sent

    def get(self, set_frame: int):
        """The plan of the window set ``set_frame`` (None: not commanded or dropped)."""
        return self.by_frame.get(set_frame)

    def add(self, frame: int, plan) -> None:
        """``plan`` was commanded for ``frame``: keep it, drop the ones too old to come back."""
        self.by_frame[frame] = plan
        for old in [k for k in self.by_frame if k < frame - KEEP_FRAMES]:
            del self.by_frame[old]

    def restart(self) -> None:
        """The stream stops (reconnect, full frame): no plan can come back."""
        self.by_frame.clear()
        self.last_commanded = 0

    def start_due(self, now: float) -> bool:
        """The stream is not running: whether to send the set that starts it at ``now`` (s)."""
        if now < self.start_wait:
            return False
        self.start_wait = now + START_EVERY_S
        self.last_commanded = 0
        return True

    def target_new(self, frame: int) -> bool:
        """Whether ``frame`` (the port's next target) has no windows commanded yet; if so it
        counts as commanded."""
        if frame <= self.last_commanded:
            return False
        self.last_commanded = frame
        return True
