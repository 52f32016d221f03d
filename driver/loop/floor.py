"""The physical floor of a gyro-coupled attitude output (steady-state Kalman analysis).

Per cross-boresight axis the attitude error is a random walk driven by the gyro's angle
random walk N (variance q = N² per second) and corrected by one measurement per frame
(variance r: the frame's stars combined, r = 1/Σ 1/σᵢ²) taken at mid-exposure every T
seconds. In steady state the prior variance at a measurement epoch is
P⁻ = (qT + √(q²T² + 4qTr)) / 2 and the posterior P⁺ = P⁻ r / (P⁻ + r). An output t seconds
after its frame's mid-exposure has σ²(t) = P⁺ + q t; the outputs that carry a frame span
t ∈ [d, d + T], d the delay from mid-exposure to the first of them, so the output floor
is √(P⁺ + q (d + T/2)) and the mid-exposure product's floor √P⁺. A gyro with a low-pass
(cut-off f_c, 2nd order) walks less over a finite window: q (Δ − κ), κ = 1/(2√2 π f_c)
(the rate noise above f_c is filtered out), which enters every window above.

Outside the floor, and outside the filter's covariance: the camera model's pointing bias. A
principal point off by δ = (δc, δr) px turns every star's direction, and so the camera's
attitude, by δr/f about the camera's x axis and δc/f about its y axis (f the focal length,
px) — the same for every star of every frame, so no update can see it and no filter lowers
it. It is reported beside the covariance, as a star tracker's bias error is reported beside
its noise: from a [camera] calibration's principal-point 1σ (:func:`pointing_bias_arcsec`).
"""

from __future__ import annotations

import math

ARCSEC = math.pi / 180.0 / 3600.0


def attitude_floor(arw: float, r: float, period_s: float, delay_s: float, kappa_s: float = 0.0) -> dict:
    """Floor (1σ per cross-boresight axis) of the real-time output and of the mid-exposure
    product, in arcsec. ``arw`` rad/√s, ``r`` rad² per frame, ``period_s`` and ``delay_s`` s;
    ``kappa_s``: the gyro low-pass's share of the walk over a window (its windows walk
    N²(Δ − κ))."""
    q = arw * arw
    qt = q * max(period_s - kappa_s, 0.0)
    p_minus = 0.5 * (qt + math.sqrt(qt * qt + 4.0 * qt * r))
    p_plus = p_minus * r / (p_minus + r) if p_minus + r > 0 else 0.0
    out = p_plus + q * max(delay_s + 0.5 * period_s - kappa_s, 0.0)
    return {"floor_arcsec": math.sqrt(out) / ARCSEC, "floor_mid_exposure_arcsec": math.sqrt(p_plus) / ARCSEC}


def pointing_bias_arcsec(principal_point_sigma_px, f_px: float) -> list[float]:
    """1σ of the camera model's pointing bias about the camera's x and y axes (arcsec) from
    the principal point's 1σ (column, row; px) and the focal length (px)."""
    sc, sr = principal_point_sigma_px
    return [sr / f_px / ARCSEC, sc / f_px / ARCSEC]


class FloorInputs:
    """Running means over a run's image updates of what the floor depends on."""

    def __init__(self):
        self.n = 0
        self.sum_r = 0.0
        self.sum_delay = 0.0
        self.t_first = None
        self.t_last = None
        self.sum_stars = 0

    def add(self, t_mid: float, t_first_output: float, r: float, n_stars: int) -> None:
        """One update: mid-exposure time, time of the first output carrying it (s), the
        frame's combined variance ``r`` (rad²) and its star count."""
        self.n += 1
        self.sum_r += r
        self.sum_delay += t_first_output - t_mid
        self.sum_stars += n_stars
        if self.t_first is None:
            self.t_first = t_mid
        self.t_last = t_mid

    def summary(self, arw: float, kappa_s: float = 0.0) -> dict:
        if self.n < 2:
            return {"floor_arcsec": None}
        period = (self.t_last - self.t_first) / (self.n - 1)
        r = self.sum_r / self.n
        delay = self.sum_delay / self.n
        res = attitude_floor(arw, r, period, delay, kappa_s)
        res.update({"floor_inputs": {"arw_rad_rts": arw, "lowpass_share_ms": kappa_s * 1e3,
                                     "frame_period_ms": period * 1e3,
                                     "exposure_to_output_ms_mean": delay * 1e3,
                                     "star_sigma_combined_arcsec": math.sqrt(r) / ARCSEC,
                                     "stars_per_update": self.sum_stars / self.n, "updates": self.n}})
        return res
