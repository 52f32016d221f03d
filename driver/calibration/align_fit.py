"""Gyro → camera rotation and gyro/camera time offset from slews.

Inputs: gyro samples ``w_g`` (N, 3) rad/s in gyro axes, stamped ``t_g`` (s, gyro clock);
star-tracker attitudes ``q_c`` (K, 4) [x, y, z, w] ICRS → camera at exposure mid-times
``t_c`` (s, camera clock).

Model: ``ω_camera(t) = R (ω_g(t − δt) − b)``: ``R`` maps gyro-frame vectors to the camera
frame, ``δt`` is the time to add to a gyro timestamp to get the camera time of the rate it
measured (it includes the gyro's filter group delay and any clock offset), ``b`` the gyro
bias. Over windows of ``lag`` camera frames the camera rotation vector
``φ_k = rotvec(q_{k+lag} ⊗ q_k⁻¹)`` is compared with ``R (G(t_{k+lag} − δt) − G(t_k − δt) − b T_k)``
(``G`` the gyro's integral, :class:`~gyrostar.calibration.gyro_integral.GyroIntegral`).
δt is observable only where the rate changes (angular acceleration): slew back and forth.

Steps: coarse δt by matching |ω| (rotation-invariant) on a grid of offsets; ``R`` by the
SVD solution of Wahba's problem on the window vectors; then Gauss–Newton on
(rotation correction, δt, b) with per-axis weights from the residuals (the roll axis of a
star tracker is several times noisier than the cross-boresight axes).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import ConfigError
from .gyro_integral import GyroIntegral
from .intrinsics import _cross_mat, rotvec_dcm
from .scale_fit import attitude_increments


@dataclass
class AlignFit:
    rotation: np.ndarray      # R, gyro → camera (3, 3)
    time_offset: float        # δt, s
    bias: np.ndarray          # rad/s, gyro axes
    rotation_sigma: np.ndarray  # 1-σ of the rotation correction (rad, camera axes)
    time_offset_sigma: float  # s
    residual_rms: np.ndarray  # per camera axis, rad
    coarse_offset: float      # s
    n_windows: int

    @property
    def quaternion(self) -> np.ndarray:
        """``R`` as [x, y, z, w] (``A(q) = R``, gyro → camera)."""
        from ..attitude import dcm_to_quat

        return dcm_to_quat(np.ascontiguousarray(self.rotation))


def wahba_svd(a: np.ndarray, b: np.ndarray, w: np.ndarray | None = None) -> np.ndarray:
    """Rotation ``R`` minimising Σ wᵢ |bᵢ − R aᵢ|² (a, b (K, 3))."""
    w = np.ones(len(a)) if w is None else w
    h = (b * w[:, None]).T @ a
    u, _, vt = np.linalg.svd(h)
    d = np.sign(np.linalg.det(u @ vt))
    return u @ np.diag([1.0, 1.0, d]) @ vt


def rotation_angle(r1: np.ndarray, r2: np.ndarray) -> float:
    """Angle (rad) of ``r1 r2ᵀ``."""
    c = (np.trace(r1 @ r2.T) - 1.0) / 2.0
    return float(np.arccos(np.clip(c, -1.0, 1.0)))


def coarse_offset(gi: GyroIntegral, t_c: np.ndarray, phi1: np.ndarray, max_offset: float,
                  step: float) -> float:
    """δt (s) on a grid ±``max_offset`` minimising the misfit of |ω| from the camera
    (frame-to-frame rotation vectors ``phi1``) and from the gyro."""
    mid = 0.5 * (t_c[1:] + t_c[:-1])
    cam = np.linalg.norm(phi1, axis=1) / np.diff(t_c)
    best, best_cost = 0.0, np.inf
    lo, hi = gi.t[0] + max_offset, gi.t[-1] - max_offset
    sel = (mid > lo) & (mid < hi)
    if sel.sum() < 10:
        raise ConfigError("too few camera epochs inside the gyro record for the time offset search")
    for d in np.arange(-max_offset, max_offset + step / 2, step):
        g = np.linalg.norm(gi.rate(mid[sel] - d), axis=1)
        cost = np.sum((cam[sel] - g) ** 2)
        if cost < best_cost:
            best, best_cost = float(d), cost
    return best


def fit_alignment(t_g: np.ndarray, w_g: np.ndarray, t_c: np.ndarray, q_c: np.ndarray, lag: int = 10,
                  max_offset: float = 0.05, coarse_step: float = 0.5e-3, iterations: int = 15) -> AlignFit:
    """Estimate ``R``, ``δt`` and ``b`` (see module docstring)."""
    t_c = np.asarray(t_c, float)
    q_c = np.asarray(q_c, float)
    if q_c.shape != (len(t_c), 4) or len(t_c) < 3 * lag + 3:
        raise ConfigError(f"need (K, 4) attitudes at K ≥ {3 * lag + 3} epochs; got {q_c.shape} and {t_c.shape}")
    if np.any(np.diff(t_c) <= 0):
        raise ConfigError("camera epochs must increase strictly")
    gi = GyroIntegral(t_g, w_g)
    inside = (t_c - max_offset > gi.t[0]) & (t_c + max_offset < gi.t[-1])
    t_c, q_c = t_c[inside], q_c[inside]
    phi1 = attitude_increments(q_c)
    d0 = coarse_offset(gi, t_c, phi1, max_offset, coarse_step)
    idx = np.arange(0, len(t_c) - lag, lag)
    t0, t1 = t_c[idx], t_c[idx + lag]
    phi = _increments(q_c, idx, lag)
    span = t1 - t0
    dt_off = d0
    bias = np.zeros(3)
    g = gi.at(t1 - dt_off) - gi.at(t0 - dt_off)
    rot = wahba_svd(g, phi)
    wax = np.ones(3)
    cov = np.full((7, 7), np.nan)
    for it in range(iterations):
        g = gi.at(t1 - dt_off) - gi.at(t0 - dt_off) - bias * span[:, None]
        pred = g @ rot.T
        res = phi - pred
        if it >= 1:
            wax = 1.0 / np.maximum(res.var(axis=0), 1e-30)
        # res ≈ res0 + J δ with δ = (ε, δt, b) and R ← (I − [ε×]) R:
        # ∂res/∂ε = −[pred×], ∂res/∂δt = R Δω (ω at the window ends), ∂res/∂b = R T_k
        dw = gi.rate(t1 - dt_off) - gi.rate(t0 - dt_off)
        jr = np.empty((len(idx), 3, 7))
        jr[:, :, 0:3] = -_cross_mat(pred)
        jr[:, :, 3] = dw @ rot.T
        jr[:, :, 4:7] = rot[None] * span[:, None, None]
        a = np.einsum("nai,a,naj->ij", jr, wax, jr)
        rhs = np.einsum("nai,a,na->i", jr, wax, res)
        delta = np.linalg.solve(a, -rhs)
        rot = rotvec_dcm(delta[None, 0:3])[0] @ rot
        dt_off += delta[3]
        bias = bias + delta[4:7]
        cov = np.linalg.inv(a)
        if np.abs(delta[:3]).max() < 1e-10 and abs(delta[3]) < 1e-9:
            break
    g = gi.at(t1 - dt_off) - gi.at(t0 - dt_off) - bias * span[:, None]
    res = phi - g @ rot.T
    return AlignFit(rot, float(dt_off), bias, np.sqrt(np.diag(cov)[:3]), float(np.sqrt(cov[3, 3])),
                    np.sqrt((res**2).mean(axis=0)), d0, len(idx))


def _increments(q: np.ndarray, idx: np.ndarray, lag: int) -> np.ndarray:
    out = np.empty((len(idx), 3))
    for n, k in enumerate(idx):
        out[n] = attitude_increments(np.stack([q[k], q[k + lag]]))[0]
    return out
