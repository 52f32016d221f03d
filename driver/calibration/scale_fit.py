"""Gyro scale factor and 3×3 misalignment by linear least squares.

Model (gyro axes, rad/s): ``ω_meas = S ω_true + b + noise``; ``S = I + diag(scale
errors) + off-diagonal misalignment``; the driver applies ``ω = S⁻¹ (ω_meas − b)``.

* Rate table: run ``k`` turns the table at a known constant rate vector ``Ω_k``; the
  mean of its samples is ``S Ω_k + b``. Needs rates about all three axes (both signs
  separate the bias), at least four independent runs.
* Slews seen by the star tracker: consecutive camera attitudes give the rotation vector
  ``φ_k`` over ``[t_k, t_{k+1}]``; the integrated gyro over the same span ``g_k`` gives
  ``φ_k = C g_k − C b Δt_k`` with ``C = S⁻¹`` (camera axes, including the mounting if the
  gyro is not yet aligned), linear in ``C`` and ``e = C b``.

Both fits refuse data that do not determine ``S`` (:func:`check_determined`, exit 1, nothing
written): the fit's own 1-σ of an element above :data:`SIGMA_MAX`, or principal scales of
``S`` (its singular values: mounting rotations do not change them) off 1 by more than
:data:`SCALE_RANGE` — a MEMS gyro's scale error is ~0.3 % (BMI088), its cross-axis a few mrad.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import ConfigError, GyrostarError

SIGMA_MAX = 0.01        # 1-σ of an element of S (or of the gyro map), 10 000 ppm: above it S is not determined
SCALE_RANGE = 0.05      # |singular value of S − 1| beyond which a fit is not a MEMS gyro's (BMI088 ~0.003)


class NotDetermined(GyrostarError):
    """The data do not determine the calibration (exit 1, a check failed); nothing is written."""

    exit_code = 1


def check_determined(what: str, matrix: np.ndarray, sigma: np.ndarray, hint: str) -> None:
    """:class:`NotDetermined` when the 1-σ ``sigma`` of ``matrix`` (S or the gyro map, unitless)
    exceeds :data:`SIGMA_MAX` or its singular values leave 1 ± :data:`SCALE_RANGE`."""
    worst = float(np.max(sigma))
    if not worst <= SIGMA_MAX:
        raise NotDetermined(f"{what}: the data do not determine it (the fit's 1σ reaches {worst * 1e6:.3g} ppm, "
                            f"limit {SIGMA_MAX * 1e6:.0f} ppm): {hint}; nothing written")
    sv = np.linalg.svd(matrix, compute_uv=False)
    if not np.all(np.abs(sv - 1.0) <= SCALE_RANGE):
        raise NotDetermined(f"{what}: the data do not determine it (fitted gyro scales "
                            f"{', '.join(f'{v:.4g}' for v in sv)}; a MEMS gyro's are 1 ± {SCALE_RANGE:g}): "
                            f"{hint}; nothing written")


@dataclass
class ScaleFit:
    """Result: sensitivity ``S``, its inverse ``correction``, bias ``b`` (rad/s), the
    per-element 1-σ of ``S`` and the fit's residual RMS (rad/s or rad)."""

    sensitivity: np.ndarray
    correction: np.ndarray
    bias: np.ndarray
    sensitivity_sigma: np.ndarray
    residual_rms: float

    @property
    def scale_factor_ppm(self) -> np.ndarray:
        """Per-axis scale-factor error (ppm): ``S_ii − 1``."""
        return (np.diag(self.sensitivity) - 1.0) * 1e6

    @property
    def misalignment_rad(self) -> np.ndarray:
        """Off-diagonal part of ``S`` (rad, small-angle cross-axis sensitivities)."""
        return self.sensitivity - np.diag(np.diag(self.sensitivity))


def run_means(gyro: np.ndarray, run: np.ndarray, n_runs: int, trim: int = 0):
    """Mean and standard error of the gyro samples of each run (``run`` holds ids
    0..n_runs-1); the first and last ``trim`` samples of each run are dropped."""
    gyro = np.asarray(gyro, float)
    run = np.asarray(run)
    if gyro.ndim != 2 or gyro.shape[1] != 3 or len(run) != len(gyro):
        raise ConfigError(f"gyro must be (N, 3) with one run id per sample; got {gyro.shape} and {run.shape}")
    means = np.empty((n_runs, 3))
    sems = np.empty((n_runs, 3))
    for k in range(n_runs):
        x = gyro[run == k]
        if trim:
            x = x[trim:len(x) - trim]
        if len(x) < 10:
            raise ConfigError(f"run {k} has {len(x)} samples after trimming; need at least 10")
        means[k] = x.mean(axis=0)
        sems[k] = x.std(axis=0, ddof=1) / np.sqrt(len(x))
    return means, sems


def fit_rate_table(table_rates: np.ndarray, means: np.ndarray) -> ScaleFit:
    """Least squares of ``means_k = S Ω_k + b`` over runs (both (K, 3), rad/s)."""
    omega = np.asarray(table_rates, float)
    y = np.asarray(means, float)
    if omega.shape != y.shape or omega.ndim != 2 or omega.shape[1] != 3:
        raise ConfigError(f"table rates {omega.shape} and run means {y.shape} must both be (K, 3)")
    design = np.column_stack([omega, np.ones(len(omega))])
    if len(omega) < 4 or np.linalg.matrix_rank(design) < 4:
        raise ConfigError("rate-table runs must include rates about all three axes and at least "
                          "four independent runs (e.g. +/- about each axis)")
    coef, *_ = np.linalg.lstsq(design, y, rcond=None)
    s = coef[:3].T
    b = coef[3]
    resid = y - design @ coef
    dof = max(len(y) - 4, 1)
    sigma2 = (resid**2).sum(axis=0) / dof
    cov_diag = np.diag(np.linalg.inv(design.T @ design))[:3]
    s_sigma = np.sqrt(np.outer(sigma2, cov_diag))
    check_determined("gyro scale factors", s, s_sigma, "give more or longer rate-table runs")
    return ScaleFit(s, np.linalg.inv(s), b, s_sigma, float(np.sqrt((resid**2).mean())))


def fit_slews(phi: np.ndarray, g: np.ndarray, dt: np.ndarray) -> ScaleFit:
    """Least squares of ``φ_k = C g_k − e Δt_k`` over camera intervals.

    ``phi`` (K, 3) rad: camera rotation vectors; ``g`` (K, 3) rad: integrated gyro over the
    same spans; ``dt`` (K,) s. Returns ``S = C⁻¹`` and ``b = C⁻¹ e``."""
    phi, g, dt = np.asarray(phi, float), np.asarray(g, float), np.asarray(dt, float)
    if phi.shape != g.shape or phi.ndim != 2 or phi.shape[1] != 3 or dt.shape != (len(phi),):
        raise ConfigError("slew fit needs phi (K,3), g (K,3) and dt (K,) of one length")
    design = np.column_stack([g, -dt])
    if np.linalg.matrix_rank(design) < 4:
        raise ConfigError("slews must turn about all three axes to observe scale and misalignment")
    coef, *_ = np.linalg.lstsq(design, phi, rcond=None)
    c = coef[:3].T
    e = coef[3]
    s = np.linalg.inv(c)
    resid = phi - design @ coef
    dof = max(len(phi) - 4, 1)
    sigma2 = (resid**2).sum(axis=0) / dof
    cov_diag = np.diag(np.linalg.inv(design.T @ design))[:3]
    c_sigma = np.sqrt(np.outer(sigma2, cov_diag))
    check_determined("gyro scale factors", s, c_sigma, "slew about all three axes at several °/s")
    return ScaleFit(s, c, s @ e, c_sigma, float(np.sqrt((resid**2).mean())))


def attitude_increments(q: np.ndarray) -> np.ndarray:
    """Rotation vectors (rad, body axes) from each attitude to the next: ``δq = q_{k+1} ⊗ q_k⁻¹``
    (``q`` (K, 4) [x, y, z, w] ICRS→body)."""
    from ..attitude import quat_conj, quat_mult

    q = np.asarray(q, float)
    out = np.empty((len(q) - 1, 3))
    for k in range(len(q) - 1):
        d = quat_mult(q[k + 1], quat_conj(q[k]))
        if d[3] < 0:
            d = -d
        ang = 2.0 * np.arctan2(np.linalg.norm(d[:3]), d[3])
        n = np.linalg.norm(d[:3])
        out[k] = d[:3] * (ang / n) if n > 1e-15 else 2.0 * d[:3]
    return out


def integrate_gyro(t_gyro: np.ndarray, gyro: np.ndarray, t_edges: np.ndarray) -> np.ndarray:
    """∫ω dt (rad) between consecutive ``t_edges`` (see :mod:`gyrostar.calibration.gyro_integral`)."""
    from .gyro_integral import GyroIntegral

    return np.diff(GyroIntegral(t_gyro, gyro).at(np.asarray(t_edges, float)), axis=0)
