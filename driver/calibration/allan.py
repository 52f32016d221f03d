"""Overlapping Allan deviation of gyro rates and the IEEE 952 noise terms.

Rates are rad/s, sample rate ``fs`` Hz, cluster times ``tau`` s. The IEEE Std 952-1997
(annex C) Allan variance of a rate gyro is the sum of independent terms, each with its
own log-log slope of the Allan *deviation*:

====================  ==========================  =========  ===========================
term                  Allan variance σ²(τ)        slope      coefficient (SI)
====================  ==========================  =========  ===========================
quantization          3 Q² / τ²                   -1         Q   (rad)
angle random walk     N² / τ                      -1/2       N   (rad/√s = rad/s/√Hz)
bias instability      (2 ln2 / π) B²              0          B   (rad/s)
rate random walk      K² τ / 3                    +1/2       K   (rad/s/√s)
Markov (correlated)   2σ²T_c/τ·[1 − T_c/(2τ)·     +½ → −½    σ (rad/s), T_c (s)
                      (3 − 4e^{−τ/T_c} + e^{−2τ/T_c})]
====================  ==========================  =========  ===========================

The bias-instability term is either the flicker floor B (flat, the IEEE reading) or, when
the bias wanders as exponentially correlated (first-order Gauss–Markov) noise, the
Markov term of annex C, whose Allan deviation peaks at 0.617 σ at τ ≈ 1.89 T_c.
``model="auto"`` fits both and keeps the Markov term only when its weighted χ² is clearly
smaller (a BIC-like margin). ``N`` is the
IEEE coefficient (two-sided PSD ``S = N²``): a one-sided noise density ``n`` (°/s/√Hz, as
datasheets and the simulator state it, ``σ_sample = n·√(fs/2)``) gives ``N = n/√2``.

:func:`fit_noise_terms` fits all four at once by non-negative weighted least squares on
σ²(τ) (weights from each point's confidence), which keeps the bias-instability floor free
of the ARW and RRW tails that bias the "read the minimum" reading;
:func:`slope_readings` gives the classic single-point readings (σ at τ = 1 s on the −½
line, minimum/0.664, σ at τ = 3 s on the +½ line) for comparison.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import ConfigError

BI_FACTOR = np.sqrt(2.0 * np.log(2.0) / np.pi)  # 0.6643: flat floor = BI_FACTOR * B


@dataclass
class AllanCurve:
    """Overlapping Allan deviation of one axis: ``tau`` (s), ``adev`` (rad/s), ``err``
    (1-σ error of ``adev`` from the equivalent degrees of freedom, :func:`edf_white`),
    ``n`` (number of overlapping terms averaged)."""

    tau: np.ndarray
    adev: np.ndarray
    err: np.ndarray
    n: np.ndarray


@dataclass
class NoiseTerms:
    """IEEE 952 coefficients (SI): Q rad, N rad/√s, K rad/s/√s, and the bias-instability
    term: ``model == "flicker"`` → floor B rad/s; ``"markov"`` → σ rad/s with correlation
    time ``markov_tau`` s. ``bias_instability`` is B or σ accordingly; ``chi2`` the fit's
    weighted χ² per point."""

    quantization: float
    arw: float
    bias_instability: float
    rrw: float
    model: str = "flicker"
    markov_tau: float = 0.0
    chi2: float = 0.0

    def adev(self, tau: np.ndarray) -> np.ndarray:
        """Model Allan deviation (rad/s) at ``tau`` (s)."""
        tau = np.asarray(tau, float)
        return np.sqrt(_design(tau, self.model, self.markov_tau) @ self._coeffs())

    def bias_term_adev(self, tau: np.ndarray) -> np.ndarray:
        """Allan deviation of the bias-instability term alone (rad/s)."""
        tau = np.asarray(tau, float)
        return np.sqrt(_design(tau, self.model, self.markov_tau)[:, 2]) * self.bias_instability

    def _coeffs(self) -> np.ndarray:
        return np.array([self.quantization**2, self.arw**2, self.bias_instability**2, self.rrw**2])


def tau_grid(n_samples: int, fs: float, per_decade: int = 12, max_fraction: float = 0.25) -> np.ndarray:
    """Log-spaced cluster times from one sample to ``max_fraction`` of the record (s),
    rounded to whole samples and unique."""
    if n_samples < 16:
        raise ConfigError(f"Allan deviation needs at least 16 samples, got {n_samples}")
    m_max = max(2, int(n_samples * max_fraction))
    m = np.unique(np.round(np.logspace(0, np.log10(m_max), int(np.log10(m_max) * per_decade) + 2)).astype(np.int64))
    return m / fs


def edf_white(n_samples: int, m: np.ndarray) -> np.ndarray:
    """Equivalent degrees of freedom of the overlapping Allan variance for white rate noise
    at cluster size ``m`` samples out of ``n_samples`` (Howe, Allan & Barnes 1981):
    ``[3(N−1)/(2m) − 2(N−2)/N] · 4m²/(4m² + 5)``. The overlapping terms are correlated, so
    ``adev/√n`` (allantools' error) is far too optimistic; σ_adev/adev ≈ 1/√(2·edf)."""
    m = np.asarray(m, float)
    n = float(n_samples)
    edf = (3.0 * (n - 1.0) / (2.0 * m) - 2.0 * (n - 2.0) / n) * 4.0 * m * m / (4.0 * m * m + 5.0)
    return np.maximum(edf, 1.0)


def block_average(rate: np.ndarray, factor: int) -> np.ndarray:
    """Mean of consecutive blocks of ``factor`` samples (drops the incomplete tail)."""
    n = (len(rate) // factor) * factor
    return rate[:n].reshape(-1, factor, *rate.shape[1:]).mean(axis=1)


def allan_deviation(rate: np.ndarray, fs: float, per_decade: int = 12, max_samples: int = 2_000_000,
                    max_fraction: float = 0.25) -> AllanCurve:
    """Overlapping Allan deviation (allantools ``oadev``) of one axis of rate samples.

    Records longer than ``max_samples`` are split: cluster times shorter than 100 samples
    of the decimated stream come from the first ``max_samples`` raw samples, longer ones
    from the whole record block-averaged by ``D = ceil(len/max_samples)``. Block averages
    are exact Allan clusters, so long-τ values lose only some overlap, not accuracy.
    """
    import allantools

    rate = np.asarray(rate, dtype=float)
    if rate.ndim != 1:
        raise ConfigError(f"allan_deviation takes one axis (1-D), got shape {rate.shape}")
    if not np.all(np.isfinite(rate)):
        raise ConfigError("gyro rates contain NaN or infinite samples")
    n = len(rate)
    taus = tau_grid(n, fs, per_decade, max_fraction)
    if n <= max_samples:
        t, ad, ade, ns = allantools.oadev(rate, rate=fs, data_type="freq", taus=taus)
        t, ad = np.asarray(t), np.asarray(ad)
        return AllanCurve(t, ad, ad / np.sqrt(2.0 * edf_white(n, np.round(t * fs))), np.asarray(ns))
    factor = int(np.ceil(n / max_samples))
    split = 100 * factor / fs
    short = taus[taus < split]
    long_ = taus[taus >= split]
    t1, a1, e1, n1 = allantools.oadev(rate[:max_samples], rate=fs, data_type="freq", taus=short)
    dec = block_average(rate, factor)
    long_ = np.unique(np.maximum(np.round(long_ * fs / factor), 1)) * factor / fs
    t2, a2, e2, n2 = allantools.oadev(dec, rate=fs / factor, data_type="freq", taus=long_)
    t, ad = np.concatenate([t1, t2]), np.concatenate([a1, a2])
    err = np.concatenate([a1 / np.sqrt(2.0 * edf_white(n, np.round(np.asarray(t1) * fs))),
                          a2 / np.sqrt(2.0 * edf_white(len(dec), np.round(np.asarray(t2) * fs / factor)))])
    return AllanCurve(t, ad, err, np.concatenate([n1, n2]))


def markov_avar(tau: np.ndarray, tc: float) -> np.ndarray:
    """Allan variance of unit-σ first-order Gauss–Markov noise with correlation time ``tc``."""
    x = tau / tc
    return (2.0 / x) * (1.0 - (3.0 - 4.0 * np.exp(-x) + np.exp(-2.0 * x)) / (2.0 * x))


def _design(tau: np.ndarray, model: str = "flicker", tc: float = 0.0) -> np.ndarray:
    bias = np.full_like(tau, BI_FACTOR**2) if model == "flicker" else markov_avar(tau, tc)
    return np.column_stack([3.0 / tau**2, 1.0 / tau, bias, tau / 3.0])


def _nnls_fit(t, a, var_sd, model, tc, quantization):
    from scipy.optimize import nnls

    design = _design(t, model, tc) / var_sd[:, None]
    if not quantization:
        design[:, 0] = 0.0
    scale = np.maximum(np.abs(design).max(axis=0), 1e-300)
    sol, rnorm = nnls(design / scale, a**2 / var_sd)
    return sol / scale, float(rnorm**2 / len(t))


def fit_noise_terms(curve: AllanCurve, tau_min: float = 0.1, model: str = "auto",
                    quantization: bool = False) -> NoiseTerms:
    """Fit Q, N, the bias-instability term and K to σ²(τ) by non-negative weighted least
    squares (``model``: "flicker", "markov" or "auto", see the module docstring).

    Points with τ < ``tau_min`` (s; where the gyro's low-pass filter correlates samples)
    are left out. Each point is weighted by the inverse of its σ² standard error, 2·σ·err.
    The Markov correlation time is searched on a log grid (the rest is linear).
    ``quantization`` adds the Q term; it is off by default because a rate-output MEMS gyro
    quantises *rate*, which is white rate noise (part of N), not the angle quantisation the
    τ⁻¹ term describes, and over a short record the extra term trades off against N.
    """
    if model not in ("auto", "flicker", "markov"):
        raise ConfigError(f"unknown bias-instability model {model!r} (auto, flicker, markov)")
    tau, ad, err, n = curve.tau, curve.adev, curve.err, curve.n
    keep = (tau >= tau_min) & (ad > 0) & (err > 0) & (n > 0)
    if keep.sum() < 5:
        raise ConfigError(f"too few Allan points above --tau-min {tau_min} s to fit the noise terms "
                          f"({int(keep.sum())}); record a longer log")
    t, a, e = tau[keep], ad[keep], err[keep]
    var_sd = 2.0 * a * np.maximum(e, 1e-3 * a)
    fits = []
    if model in ("auto", "flicker"):
        sol, chi2 = _nnls_fit(t, a, var_sd, "flicker", 0.0, quantization)
        fits.append((chi2, sol, "flicker", 0.0))
    if model in ("auto", "markov"):
        for tc in np.logspace(np.log10(max(1.0, 10.0 * t[0])), np.log10(max(t[-1], 10.0)), 60):
            sol, chi2 = _nnls_fit(t, a, var_sd, "markov", tc, quantization)
            fits.append((chi2, sol, "markov", float(tc)))
    best = min(fits, key=lambda f: f[0])
    if model == "auto" and best[2] == "markov":
        # the Markov term has one parameter more (T_c) and, with T_c short, mimics ARW:
        # keep the flicker floor unless the Markov fit is clearly better (total χ² drop
        # above 2 ln n + 6, a BIC-like margin)
        n_pts = len(t)
        if (fits[0][0] - best[0]) * n_pts < 2.0 * np.log(n_pts) + 6.0:
            best = fits[0]
    chi2, sol, kind, tc = best
    c = np.sqrt(sol)
    return NoiseTerms(quantization=float(c[0]), arw=float(c[1]), bias_instability=float(c[2]), rrw=float(c[3]),
                      model=kind, markov_tau=tc, chi2=chi2)


def slope_readings(curve: AllanCurve) -> dict:
    """Classic IEEE 952 single-slope readings: N = σ(1 s) of the −½ line fitted where the
    local slope is near −½, B = min σ / 0.664, K = σ(3 s) of the +½ line (NaN if no
    +½ region). Units as :class:`NoiseTerms`."""
    tau, ad = curve.tau, curve.adev
    lt, la = np.log10(tau), np.log10(ad)
    slope = np.gradient(la, lt)
    out = {}
    for name, s, tau_ref in (("arw", -0.5, 1.0), ("rrw", 0.5, 3.0)):
        sel = np.abs(slope - s) < 0.1
        sel &= (tau >= 0.1) if s < 0 else (tau > tau[np.argmin(ad)])
        out[name] = float(10 ** np.median(la[sel] - s * lt[sel] + s * np.log10(tau_ref))) if sel.any() else float("nan")
    out["bias_instability"] = float(ad.min() / BI_FACTOR)
    out["tau_at_minimum"] = float(tau[np.argmin(ad)])
    return out
