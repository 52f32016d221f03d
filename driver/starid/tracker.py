"""Star-identification state machine: lost-in-space → tracking → back on failure.

``LOST``: every image goes to the lost-in-space identifier (Pyramid). On an accepted
result the tracker keeps its attitude and enters ``TRACKING``.
``TRACKING``: the attitude is propagated to the new image with the gyro (body rate ω in
rad/s over ``dt`` s, or an integrated body-frame rotation ``dq`` with
``q_new = dq ⊗ q_old``) and the image goes to the tracking identifier (extended grid).
If that is rejected, the same image goes to Pyramid; if Pyramid also fails the tracker
is ``LOST`` and reports the failure. Every result it returns has passed the QUEST
residual verification of its identifier; a rejected one is returned with ``ok`` False
and no ids, never a guess. A tracking result with fewer than ``min_track_stars``
identified stars is not trusted (with three stars one false star near a catalog position
can pass the residual check and pull the boresight by ~10 px): the image goes to Pyramid.
Measured magnitudes, when given, go to both identifiers' per-star checks
(:mod:`gyrostar.starid.star_check`).
"""

from __future__ import annotations

import dataclasses
import enum

import numpy as np

from ..attitude import quat_mult, quat_normalize, quat_propagate
from ..errors import ConfigError
from .result import StarIdResult


class Mode(enum.Enum):
    LOST = "lost"
    TRACKING = "tracking"


@dataclasses.dataclass
class StarTracker:
    """``lost_in_space``: identifier with ``identify(uv, mag=None)`` (Pyramid); ``tracking``:
    with ``identify(uv, q_pred, mag=None)`` (extended grid). Counters say how often each
    path ran."""

    lost_in_space: object
    tracking: object
    min_track_stars: int = 4
    mode: Mode = Mode.LOST
    q: np.ndarray | None = None
    counts: dict = dataclasses.field(default_factory=lambda: {"tracked": 0, "acquired": 0, "fallback": 0,
                                                                 "failed": 0})

    def predict(self, omega=None, dt: float = 0.0, dq=None) -> np.ndarray:
        """The attitude at the new image from the last one and the gyro."""
        if self.q is None:
            raise ConfigError("no attitude to propagate (tracker is lost)")
        if dq is not None:
            dq = np.asarray(dq, dtype=np.float64)
            if dq.shape != (4,) or not np.all(np.isfinite(dq)):
                raise ConfigError("dq must be a finite quaternion [x, y, z, w]")
            return quat_normalize(quat_mult(dq, self.q))
        w = np.zeros(3) if omega is None else np.asarray(omega, dtype=np.float64)
        if w.shape != (3,) or not np.all(np.isfinite(w)) or not np.isfinite(dt) or dt < 0:
            raise ConfigError("omega must be 3 finite rates (rad/s) and dt a finite time ≥ 0 (s)")
        return quat_propagate(self.q, w, float(dt))

    def update(self, uv, omega=None, dt: float = 0.0, dq=None, mag=None) -> StarIdResult:
        """Identify one image's centroids ``uv`` (n, 2) px, brightest first; ``mag`` (n,)
        their calibrated measured V, or None (position-only per-star checks)."""
        if self.mode is Mode.TRACKING:
            q_pred = self.predict(omega, dt, dq)
            r = self.tracking.identify(uv, q_pred) if mag is None else self.tracking.identify(uv, q_pred, mag=mag)
            if r.ok and r.n_identified >= self.min_track_stars:
                self.q = r.q
                self.counts["tracked"] += 1
                return r
            self.counts["fallback"] += 1
        r = self.lost_in_space.identify(uv) if mag is None else self.lost_in_space.identify(uv, mag=mag)
        if r.ok:
            self.mode, self.q = Mode.TRACKING, r.q
            self.counts["acquired"] += 1
        else:
            self.mode, self.q = Mode.LOST, None
            self.counts["failed"] += 1
        return r

    def reset(self) -> None:
        """Forget the attitude (next image goes to lost-in-space)."""
        self.mode, self.q = Mode.LOST, None
