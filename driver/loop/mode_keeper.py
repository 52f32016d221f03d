"""Mode keeper: the loop's mode, and the image flags its outputs carry, fed by each frame's
outcome (how many stars it updated) and by frames that stop coming.

The glue between :class:`~gyrostar.loop.stream_images.StreamImages` (which streamed outcomes
the mode machine hears) and :mod:`gyrostar.loop.modes` (the transitions, a pure function).
It touches no device, filter or track: what an outcome asks of the loop comes back as a
:class:`Heard` (clear the attitude, acquire now, count a failed acquisition, check the tracks
for lost stars), and the loop carries it out. Times are the loop's clock (s).
"""

from __future__ import annotations

from dataclasses import dataclass

from . import modes
from . import record as R
from .stream_images import StreamImages


@dataclass(frozen=True)
class Heard:
    """What an outcome the mode machine heard asks of the loop."""

    action: modes.Action      # LOSE_ATTITUDE (filter invalid, tracks cleared), ACQUIRE_NOW, ACQUISITION_FAILED
    check_tracks: bool        # drop the tracked stars lost meanwhile (not for an image heard in ACQUIRE)
    tracking: bool            # the mode after it is TRACK (the tracks' miss limit applies)


class ModeKeeper:
    """``params``: :class:`modes.ModeParams`; ``streaming``: the head streams frames (short
    runs of starless frames are flagged only, missing frames count); ``few_frames``,
    ``gap_frames``: :class:`StreamImages`' counts (frames)."""

    def __init__(self, params: modes.ModeParams, streaming: bool, few_frames: int, gap_frames: int) -> None:
        self.p = params
        self.streaming = bool(streaming)
        self.state = modes.ModeState()
        self.flags = R.FLAG_FEW_STARS       # image flags of every output until the next image
        self.changes: list = []             # (t s, from mode name, to mode name)
        self.stream_images = StreamImages(few_frames, gap_frames)

    @property
    def mode(self) -> int:
        return self.state.mode

    def enter(self, state: modes.ModeState, t: float) -> None:
        """The mode machine's new ``state`` at ``t`` (a change is recorded)."""
        if state.mode != self.state.mode:
            self.changes.append((float(t), R.MODE_NAMES[self.state.mode], R.MODE_NAMES[state.mode]))
        self.state = state

    def head_lost(self, t: float) -> None:
        """The head link went down at ``t``: the outputs say so; TRACK coasts."""
        self.flags |= R.FLAG_LINK_ERROR | R.FLAG_FEW_STARS
        self.enter(modes.on_head_lost(self.state, t), t)

    def link_error(self) -> None:
        """A frame failed on the link (the link stays up): flagged until the next image."""
        self.flags |= R.FLAG_LINK_ERROR

    def acquired(self, t: float) -> None:
        """A lost-in-space identification set a new attitude at ``t``: the next images confirm it."""
        self.enter(modes.on_acquired(self.state), t)

    def restart_stream(self, t: float) -> None:
        """The stream (re)starts at ``t``: no frame is missing before its first one is due."""
        self.stream_images.restart(t)

    def image(self, now: float, updated: int) -> Heard | None:
        """An image at ``now`` updated ``updated`` stars (0: it failed). Returns what it asks
        of the loop, or None when the mode machine does not hear it (a short run of starless
        frames while streaming and tracking: flagged only)."""
        few = updated < self.p.min_stars
        if not self.stream_images.image(now, few, self.streaming and self.state.mode == R.MODE_TRACK):
            self.flags = (R.FLAG_IMAGE_UPDATE if updated else 0) | R.FLAG_FEW_STARS
            return None
        prev = self.state.mode
        state, act = modes.on_image(self.state, now, updated, self.p)
        self.enter(state, now)
        if prev == R.MODE_ACQUIRE:
            return Heard(act, False, False)
        self.flags = (R.FLAG_IMAGE_UPDATE if updated else 0) | (R.FLAG_FEW_STARS if few else 0)
        return Heard(act, True, self.state.mode == R.MODE_TRACK)

    def frame_missing(self, now: float, period_s: float, link_up: bool) -> Heard | None:
        """Streaming, the link up, tracking or coasting: once no frame has come for
        ``gap_frames`` periods of ``period_s``, each further period counts as an image that
        updated no star (the modes coast and time out as for starless frames, and the outputs
        say so instead of TRACK on a gyro-only attitude). Returns what it asks, or None."""
        if not self.streaming or not link_up or self.state.mode == R.MODE_ACQUIRE:
            return None
        if not self.stream_images.frame_missing(now, period_s):
            return None
        heard = self.image(now, 0)
        self.stream_images.missing_counted(now, period_s)
        return heard
