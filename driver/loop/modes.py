"""The loop's mode machine: a pure function of (state, event, parameters).

Modes (:mod:`gyrostar.loop.record`): ACQUIRE (no confirmed attitude: full frames and
lost-in-space identification, then images that must confirm it) → TRACK (the last image
updated at least ``min_stars`` stars) → COAST (fewer: attitude on the bias-corrected gyro
alone) → TRACK when stars come back, or ACQUIRE after ``coast_timeout_s``.

Events: :func:`on_image` (an image was processed; ``updated`` stars passed the filter's
gate, 0 for a failed image), :func:`on_head_lost` (the link to the head is down),
:func:`on_acquired` (a lost-in-space identification set a new attitude). Each returns the
new :class:`ModeState` and the :data:`Action` flags the loop must carry out. No clock,
no devices, no loop object: every transition has a unit test (tests/loop/test_loop_modes.py).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from enum import IntFlag

from .record import MODE_ACQUIRE, MODE_COAST, MODE_TRACK


@dataclass(frozen=True)
class ModeParams:
    """Thresholds of the mode machine (units in the names)."""

    min_stars: int = 2                 # stars an image must update to count as tracking
    confirm_images: int = 20           # images without confirmation before a fresh identification is dropped
    coast_timeout_s: float = 5.0       # s in COAST before a new acquisition


@dataclass(frozen=True)
class ModeState:
    mode: int = MODE_ACQUIRE
    coast_since_s: float | None = None  # host s when COAST began
    confirm_failures: int = 0           # ACQUIRE: images since the identification that did not confirm it


class Action(IntFlag):
    NONE = 0
    LOSE_ATTITUDE = 1        # the attitude is no longer valid: clear the star tracks
    ACQUIRE_NOW = 2          # take a full frame at once
    ACQUISITION_FAILED = 4   # count a failed acquisition


def _enter(state: ModeState, mode: int, t: float) -> ModeState:
    if mode == state.mode:
        return state
    return replace(state, mode=mode, coast_since_s=t if mode == MODE_COAST else None)


def on_image(state: ModeState, t: float, updated: int, p: ModeParams) -> tuple[ModeState, Action]:
    """An image was processed at host time ``t`` (s); ``updated`` stars passed the gate."""
    enough = updated >= p.min_stars
    if state.mode == MODE_ACQUIRE:
        if enough:
            return replace(_enter(state, MODE_TRACK, t), confirm_failures=0), Action.NONE
        failures = state.confirm_failures + 1
        if failures >= p.confirm_images:
            return replace(state, confirm_failures=0), Action.LOSE_ATTITUDE | Action.ACQUISITION_FAILED
        return replace(state, confirm_failures=failures), Action.NONE
    if enough:
        return _enter(state, MODE_TRACK, t), Action.NONE
    if state.mode == MODE_TRACK:
        return _enter(state, MODE_COAST, t), Action.NONE
    # COAST
    if state.coast_since_s is not None and t - state.coast_since_s > p.coast_timeout_s:
        return _enter(state, MODE_ACQUIRE, t), Action.LOSE_ATTITUDE | Action.ACQUIRE_NOW
    return state, Action.NONE


def on_head_lost(state: ModeState, t: float) -> ModeState:
    """The head link went down at ``t``: TRACK coasts; other modes stay."""
    if state.mode == MODE_TRACK:
        return _enter(state, MODE_COAST, t)
    return state


def on_acquired(state: ModeState) -> ModeState:
    """A new identification: the next images confirm it (the mode stays ACQUIRE until then)."""
    return replace(state, confirm_failures=0)
