"""Star tracks and their windows: which catalog stars the loop follows, and where to read.

:class:`StarTracks` holds up to ``max_stars`` slots (catalog vector, navigation index, id,
miss and reject counts, latest predicted centroid px). Stars enter from the catalog
around the current attitude (the gyro-extended field: the attitude is propagated by the
gyro between images), leave when they reach the sensor edge, miss too many images, or fail
the filter's gate ``wrong_id_rejects`` times in a row. A star dropped that way is kept out
for a while that doubles with each such drop (:meth:`drop_wrong`: 1, 2, 4 … 32 s): a star
whose image a hot pixel or an unresolved neighbour pulls off its catalog place would
otherwise come back at once and fail again, frame after frame. A blended star (``blended``:
a neighbour on the sensor whose light shares its spot, :mod:`gyrostar.starid.blends`) is
taken only while fewer than ``BLEND_ADMIT_BELOW`` others are tracked, and dropped once that
many clean ones are: its centroid is not at its catalog place. :meth:`plan` builds the windows of
the next exposure for every tracked star (trajectory over the exposure and the command
lag from the current rate, :func:`gyrostar.loop.image_kernels.plan_tracked`).
"""

from __future__ import annotations

import math

import numpy as np

from ..attitude import quat_to_dcm
from . import record as R
from .image_kernels import lost_slots, plan_tracked
from .kernels import project_refs

MODEL = 1                # core.motion.MODEL_PINHOLE
BLEND_ADMIT_BELOW = 4    # blended stars are tracked only while fewer clean ones than this are tracked
BAN_FIRST_S = 1.0        # a star dropped as a wrong identification stays out this long (s),
BAN_MAX_S = 32.0         # twice as long after each further such drop, at most this long
STREAK_BORDER_PX = 2     # px of background kept on each side of a streak longer than the window square


class StarTracks:
    def __init__(self, params, camera, star_index, blended=None):
        self.p = params
        self.camera = camera
        self.cam = camera.as_array()
        self.f_px = camera.focal_length_px
        self.index = star_index
        # (len(star_index),) bool: a star whose spot is a blend (None: none known)
        n_index = 0 if star_index is None else len(star_index)
        self.blended = np.zeros(n_index, np.bool_) if blended is None else np.asarray(blended, np.bool_)
        if self.blended.shape != (n_index,):
            raise ValueError(f"blended mask has shape {self.blended.shape}, the star index {n_index} stars")
        S = R.MAX_STARS
        self.active = np.zeros(S, np.bool_)
        self.ref = np.zeros((S, 3))
        self.nav = -np.ones(S, np.int64)       # navigation-star index of each slot
        self.ids = -np.ones(S, np.int32)       # catalog id
        self.misses = np.zeros(S, np.int64)
        self.rejects = np.zeros(S, np.int64)
        self.uv = np.zeros((S, 2))             # predicted centroid (col, row) px at the last output
        self.version = 0                       # changes whenever the set of tracked stars changes
        self._kernel_version = -1              # version of the arrays kernel_stars() made last
        self._kernel = (np.zeros((0, 3)), np.zeros(0, np.int32), np.zeros(0, np.int64))
        self.strikes: dict[int, int] = {}      # navigation index → wrong-identification drops
        self.banned_until: dict[int, float] = {}   # navigation index → time (s) it may come back

    # -- slots ---------------------------------------------------------------------------
    def clear(self) -> None:
        self.active[:] = False
        self.nav[:] = -1
        self.ids[:] = -1
        self.version += 1

    def drop(self, s: int) -> None:
        self.active[s] = False
        self.nav[s] = -1
        self.ids[s] = -1
        self.version += 1

    def drop_wrong(self, s: int, now: float) -> None:
        """Drop slot ``s`` as a wrong or unusable identification and keep its star out for
        ``BAN_FIRST_S`` × 2^(drops before) s (at most ``BAN_MAX_S``)."""
        nav = int(self.nav[s])
        k = self.strikes.get(nav, 0)
        self.strikes[nav] = k + 1
        self.banned_until[nav] = now + min(BAN_FIRST_S * 2.0 ** k, BAN_MAX_S)
        self.drop(s)

    def tracked(self) -> np.ndarray:
        return np.flatnonzero(self.active)

    def kernel_stars(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The tracked stars as the predict kernel takes them: catalog vectors (k, 3), ids
        (k,) int32 and slots (k,) int64, contiguous, in slot order — made again only when the
        set of tracked stars has changed (:attr:`version`)."""
        if self.version != self._kernel_version:
            self._kernel_version = self.version
            slots = self.tracked()
            self._kernel = (np.ascontiguousarray(self.ref[slots]), np.ascontiguousarray(self.ids[slots]), slots)
        return self._kernel

    def mags(self, slots) -> np.ndarray:
        return self.index.vmag[self.nav[slots]] if len(slots) else np.zeros(0)

    def fill_from_catalog(self, q, now: float = -math.inf) -> None:
        """Fill free slots with catalog stars attitude ``q`` puts on the sensor, brightest
        first, skipping one closer than ``neighbour_sep_px`` to a tracked star and one kept
        out until after ``now`` (s) by :meth:`drop_wrong`; blended stars after all clean ones,
        and only up to ``BLEND_ADMIT_BELOW`` tracked stars."""
        free = [s for s in range(self.p.max_stars) if not self.active[s]]
        if not free:
            return
        cam = self.camera
        boresight = quat_to_dcm(q)[2]
        radius = math.atan(0.5 * math.hypot(cam.width_px, cam.height_px) / self.f_px)
        cand = self.index.cone(boresight, radius, self.p.mag_limit)
        if len(cand) == 0:
            return
        cand = cand[np.argsort(self.index.vmag[cand], kind="stable")]
        uv, ok = project_refs(self.cam, q, np.ascontiguousarray(self.index.vectors[cand]))
        margin = self.p.window_k + 8
        inside = ok & (uv[:, 0] > margin) & (uv[:, 1] > margin) \
            & (uv[:, 0] < cam.width_px - 1 - margin) & (uv[:, 1] < cam.height_px - 1 - margin)
        tracked = set(self.nav[self.active].tolist())
        sep = self.p.neighbour_sep_px
        fi = 0
        # clean stars first (brightest first within each kind); blended ones only while fewer
        # than BLEND_ADMIT_BELOW are tracked
        order = np.flatnonzero(inside)
        order = order[np.argsort(self.blended[cand[order]], kind="stable")]
        for j in order:
            nav = int(cand[j])
            if fi >= len(free) or (self.blended[nav] and len(tracked) >= BLEND_ADMIT_BELOW):
                break
            if nav in tracked or self.banned_until.get(nav, -math.inf) > now:
                continue
            act = self.active
            if np.any(act & (np.abs(uv[j, 0] - self.uv[:, 0]) < sep) & (np.abs(uv[j, 1] - self.uv[:, 1]) < sep)):
                continue
            s = free[fi]
            self.ref[s] = self.index.vectors[nav]
            self.nav[s] = nav
            self.ids[s] = int(self.index.ids[nav])
            self.active[s] = True
            self.misses[s] = 0
            self.rejects[s] = 0
            self.uv[s] = uv[j]
            tracked.add(nav)
            fi += 1
        if fi:
            self.version += 1
        self._release_blends()

    def _release_blends(self) -> None:
        """Drop the tracked blended stars once ``BLEND_ADMIT_BELOW`` clean ones are tracked:
        a sparse field let them in, and clean stars have come onto the sensor since."""
        act = self.tracked()
        blend = self.blended[self.nav[act]]
        if blend.any() and np.count_nonzero(~blend) >= BLEND_ADMIT_BELOW:
            for s in act[blend]:
                self.drop(int(s))

    def drop_lost(self, tracking: bool) -> None:
        """Drop stars that left the sensor, or (``tracking``) missed more than ``max_misses``
        images in a row while others were measured."""
        for s in lost_slots(self.active, self.uv, self.misses, self.camera.width_px, self.camera.height_px,
                            self.p.max_misses, tracking):
            self.drop(int(s))

    # -- windows -------------------------------------------------------------------------
    def plan(self, q, omega, bias, sigma_att_rad: float, lag_s: float, lag_jitter_s: float, odr_hz: float,
             budget=None):
        """Windows of the next exposure for every tracked star, brightest first within the
        head's budgets: ``(spans, window slots, per-window trajectory offsets...)`` as a dict,
        or None when no star gets a window. ``lag_s``: commanding → exposure start (s).
        ``budget`` (:class:`gyrostar.loop.linkbudget.LinkBudget`): the link's per-frame pixel
        and span budgets too, and no uncertainty margin while it says windows are tightened;
        the plan then holds ``n_stars`` (tracked stars it was made for)."""
        n_stars = int(np.count_nonzero(self.active))
        if not n_stars:
            return None
        p = self.p
        m = max(1, int(round(p.exposure_s * odr_hz)))
        sig_px = sigma_att_rad * self.f_px
        speed = math.sqrt(float(omega @ omega)) * self.f_px          # px/s near the boresight
        margin = 3.0 * sig_px + speed * lag_jitter_s
        # a streak longer than the square fills about half of its window's pixels, and the
        # window's median background then sits on the star: its faint stars go undetected (10 °/s
        # on a UART with tightened windows: 2 of 8 measured). Such windows keep a border.
        k_base = p.window_k + (2 * STREAK_BORDER_PX if speed * p.exposure_s > p.window_k else 0)
        k = min(k_base + 2 * int(math.ceil(margin)), 40)
        pixel_budget, max_spans = p.pixel_budget, p.max_spans
        if budget is not None:
            if not budget.margin_allowed():
                k = k_base                          # degrade step 2: tighter windows
            px, sp = budget.limits(n_stars)
            pixel_budget, max_spans = min(pixel_budget, px), min(max_spans, sp)
        spans, wins, off, off_start, off_len, nav = plan_tracked(
            self.active, self.nav, self.index.vmag, self.ref, q, omega, bias, m, max(float(lag_s), 0.0),
            p.exposure_s / m, self.cam,
            MODEL, k, self.camera.height_px, self.camera.width_px, pixel_budget, p.max_window_pixels, max_spans)
        if not len(wins):
            return None
        return {"spans": spans, "wins": wins, "nav": nav, "off": off, "off_start": off_start,
                "off_len": off_len, "n_stars": n_stars, "vmag": np.ascontiguousarray(self.index.vmag[nav], np.float64)}
