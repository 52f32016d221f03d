"""Per-star verification after the attitude solution: every label must fit on its own.

An identifier's labels (``match``: navigation-star index per centroid, -1 none) pass the
group test of :mod:`gyrostar.starid.verify` when their residuals are within a tolerance.
:class:`StarCheck` then judges each star alone and re-solves without the ones that fail:

* position: the residual angle ∠(b_i, A(q) r_i) in units of the centroid noise σ
  (``sigma_px`` / focal length, rad), χ² = (res/σ)² with 2 degrees of freedom;
* magnitude (when the caller gives calibrated measured V ``mag`` per centroid, NaN for
  unknown): χ² += ((m_i − V_i)/σ_m)², 3 degrees of freedom.

The star whose χ² exceeds its gate (the χ² quantile that rejects a true star with
probability ``p_reject``) by the most is unlabelled, QUEST is solved again over the rest,
and so on until all pass. With magnitudes, a label on a catalog star the sensor detects
with probability below ``p_detect_min`` (Φ((mag_limit − V)/σ_m)) is dropped too, as long
as at least ``min_safe`` labels on surely-detected stars remain: a faint catalog star is
often missing from the image, and a spurious spot near its position is then as likely as
the star itself. Fewer than ``min_stars`` verified labels reject the identification.
The attitude returned is QUEST over the verified labels only (q ICRS → body).
"""

from __future__ import annotations

import dataclasses
import math
import statistics

import numpy as np
from numba import njit

from ..errors import ConfigError
from .verify import residuals, solve


def chi2_gate(p_reject: float, dof: int) -> float:
    """The χ² value a true star exceeds with probability ``p_reject`` (2 or 3 dof)."""
    if not (0.0 < p_reject < 1.0) or dof not in (2, 3):
        raise ConfigError(f"chi2_gate needs 0 < p_reject < 1 and 2 or 3 dof, got {p_reject}, {dof}")
    from scipy.special import chdtri  # χ² inverse survival function (scipy.stats costs ~2 s to import)

    return float(chdtri(dof, p_reject))


@njit(cache=True)
def _gate_loop(b, mag, ref, vmag, match, inv_s2, inv_m2, gate2, gate3, min_stars):
    """Unlabel the worst star beyond its χ² gate and re-solve, until all pass. ``(q, n)``."""
    n = b.shape[0]
    while True:
        m = 0
        for i in range(n):
            if match[i] >= 0:
                m += 1
        if m < min_stars:
            match[:] = -1
            return np.array([0.0, 0.0, 0.0, 1.0]), 0
        q = solve(b, ref, match)
        res = residuals(q, b, ref, match)
        worst = -1
        wexcess = 1.0
        for i in range(n):
            s = match[i]
            if s < 0:
                continue
            c = res[i] * res[i] * inv_s2
            g = gate2
            if np.isfinite(mag[i]):
                d = mag[i] - vmag[s]
                c += d * d * inv_m2
                g = gate3
            if c / g > wexcess:
                wexcess = c / g
                worst = i
        if worst < 0:
            return q, m
        match[worst] = -1


@njit(cache=True)
def check_stars(b, mag, ref, vmag, match, sigma, mag_sigma, gate2, gate3, v_safe, min_safe, min_stars):
    """Per-star χ² verification (in place on ``match``). Returns ``(q, n_ok)``.

    ``b`` (n, 3) body unit vectors; ``mag`` (n,) measured V (NaN: unknown); ``ref`` (N, 3)
    and ``vmag`` (N,) catalog vectors and V; ``sigma`` centroid noise (rad, 1σ per axis);
    ``mag_sigma`` (mag); ``gate2``/``gate3`` χ² gates for 2/3 dof; ``v_safe``: faintest
    catalog V kept when ≥ ``min_safe`` verified labels are no fainter (inf: no such rule).
    ``n_ok`` below ``min_stars`` (at least 2) means rejected (``match`` then all -1)."""
    need = max(min_stars, 2)
    inv_s2 = 1.0 / (sigma * sigma)
    inv_m2 = 1.0 / (mag_sigma * mag_sigma)
    q, m = _gate_loop(b, mag, ref, vmag, match, inv_s2, inv_m2, gate2, gate3, need)
    if m == 0:
        return q, 0
    # photometric rule: only surely-detected catalog stars while there are enough of them
    n_safe = 0
    n_faint = 0
    for i in range(b.shape[0]):
        if match[i] >= 0 and np.isfinite(mag[i]):
            if vmag[match[i]] <= v_safe:
                n_safe += 1
            else:
                n_faint += 1
    if n_faint > 0 and n_safe >= max(need, min_safe):
        for i in range(b.shape[0]):
            if match[i] >= 0 and np.isfinite(mag[i]) and vmag[match[i]] > v_safe:
                match[i] = -1
        q, m = _gate_loop(b, mag, ref, vmag, match, inv_s2, inv_m2, gate2, gate3, need)
    return q, m


@dataclasses.dataclass(frozen=True)
class StarCheck:
    """Per-star χ² verification stage (see the module text).

    ``sigma_px``: centroid noise (px, 1σ per axis); ``focal_px``: focal length (px);
    ``mag_sigma``: 1σ of measured minus catalog V (mag), sensor and catalog together;
    ``mag_limit``: the sensor's limiting V; ``p_reject``: chance a true star fails its gate;
    ``p_detect_min``: smallest detection probability of a catalog star that may be
    labelled while ``min_safe`` brighter labels remain (0 disables); ``min_stars``: verified
    labels needed to accept."""

    sigma_px: float
    focal_px: float
    mag_sigma: float = 0.3
    mag_limit: float = 7.5
    p_reject: float = 1e-3
    p_detect_min: float = 0.9
    min_stars: int = 3
    min_safe: int = 4

    def __post_init__(self) -> None:
        if not (self.sigma_px > 0 and self.focal_px > 0 and self.mag_sigma > 0 and math.isfinite(self.mag_limit)):
            raise ConfigError("StarCheck needs sigma_px > 0, focal_px > 0, mag_sigma > 0 and a finite mag_limit")
        if not (0.0 < self.p_reject < 1.0 and 0.0 <= self.p_detect_min < 1.0 and self.min_stars >= 2):
            raise ConfigError("StarCheck needs 0 < p_reject < 1, 0 ≤ p_detect_min < 1 and min_stars ≥ 2")
        object.__setattr__(self, "gate2", chi2_gate(self.p_reject, 2))
        object.__setattr__(self, "gate3", chi2_gate(self.p_reject, 3))
        v_safe = (self.mag_limit - statistics.NormalDist().inv_cdf(self.p_detect_min) * self.mag_sigma
                  if self.p_detect_min > 0 else math.inf)
        object.__setattr__(self, "v_safe", v_safe)
        object.__setattr__(self, "sigma_rad", self.sigma_px / self.focal_px)

    def settings(self) -> np.ndarray:
        """The scalars of :func:`check_stars` in its argument order (for compiled callers)."""
        return np.array([self.sigma_rad, self.mag_sigma, self.gate2, self.gate3, self.v_safe, self.min_safe,
                         self.min_stars], dtype=np.float64)

    def apply(self, b: np.ndarray, mag, ref: np.ndarray, vmag: np.ndarray, match: np.ndarray):
        """Verify ``match`` (n,) for body vectors ``b`` (n, 3) and measured V ``mag`` (n,)
        or None. Returns ``(q, match, n_ok)``: a new match array, -1 where unverified."""
        n = b.shape[0]
        if mag is None:
            m = np.full(n, np.nan)
        else:
            m = np.ascontiguousarray(mag, dtype=np.float64).reshape(-1)
            if m.shape[0] != n:
                raise ConfigError(f"{m.shape[0]} magnitudes for {n} centroids")
        out = np.array(match, dtype=np.int64, copy=True)
        q, n_ok = check_stars(np.ascontiguousarray(b, dtype=np.float64), m, ref, vmag, out, self.sigma_rad,
                              self.mag_sigma, self.gate2, self.gate3, self.v_safe, self.min_safe,
                              self.min_stars)
        return q, out, int(n_ok)
