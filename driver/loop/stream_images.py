"""Streaming head: which frame outcomes the mode machine hears.

At 100 Hz one frame read with a late window set, or a frame that lost a star or two, is
no reason to coast: while tracking, fewer than :data:`STREAM_FEW_FRAMES` frames in a row
with too few stars are only flagged (:meth:`StreamImages.image` says the modes need not
hear them). And frames that stop coming while the link stays up (all lost on the link,
the head silent) must not leave the outputs saying TRACK over a gyro-only attitude: once
no frame has come for :data:`STREAM_GAP_FRAMES` frame periods, each further period counts
as an image that updated no star (:meth:`StreamImages.frame_missing`), so the modes coast
and time out to ACQUIRE as for starless frames. Times are the loop's clock (s). Both counts
are the flatsat config's ``loop.stream_few_frames`` and ``loop.stream_gap_frames``; the
constants here are their defaults.
"""

from __future__ import annotations

import math

STREAM_FEW_FRAMES = 3   # frames: consecutive images with too few stars before COAST (30 ms at 100 Hz)
STREAM_GAP_FRAMES = 3   # frames: periods without any frame before each further one counts as starless


class StreamImages:
    def __init__(self, few_frames: int = STREAM_FEW_FRAMES, gap_frames: int = STREAM_GAP_FRAMES) -> None:
        if few_frames < 1 or gap_frames < 1:
            raise ValueError(f"stream frame counts must be ≥ 1, got {few_frames} and {gap_frames}")
        self.few_frames = int(few_frames)
        self.gap_frames = int(gap_frames)
        self.few_run = 0               # consecutive images that updated too few stars
        self.t_image = -math.inf       # time of the last image (or missing frame) counted

    def restart(self, now: float) -> None:
        """The stream (re)starts at ``now``: its first frame takes a while, none is missing yet."""
        self.t_image = now

    def image(self, now: float, few: bool, tracking_stream: bool) -> bool:
        """An image at ``now`` (``few``: it updated too few stars). Returns whether the mode
        machine hears it: not a short run of such images while streaming and tracking."""
        self.t_image = now
        self.few_run = self.few_run + 1 if few else 0
        return not (tracking_stream and 0 < self.few_run < self.few_frames)

    def frame_missing(self, now: float, period: float) -> bool:
        """Whether a frame period (``period`` s) without a frame counts as a starless image at
        ``now``: after ``gap_frames`` periods without any, one per further period (call
        :meth:`missing_counted` after hearing it)."""
        return now - self.t_image > self.gap_frames * period

    def missing_counted(self, now: float, period: float) -> None:
        """The missing frame at ``now`` was counted: the next one a period later."""
        self.t_image = now - (self.gap_frames - 1) * period
