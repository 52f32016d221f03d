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

Steps (:func:`fit_alignment`): the window increments against a general linear map ``M``
(the rotation and the gyro's scale/cross-axis errors, so these do not leak into δt) and the
bias, by weighted least squares for each δt (each window weighted by its noise: the camera's
and the gyro's walk over its span); δt from the profile likelihood (each camera axis
its own noise: the roll axis of a star tracker is several times noisier than the
cross-boresight axes); ``R`` the rotation factor of ``M``.

Data that do not determine ``R`` are refused (:class:`~gyrostar.calibration.scale_fit.NotDetermined`,
exit 1): the fit's 1-σ of the rotation above :data:`ROTATION_SIGMA_MAX` on an axis, of δt
above :data:`OFFSET_SIGMA_MAX`, or ``M`` not a MEMS gyro's (``scale_fit.check_determined``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import ConfigError
from .gyro_integral import GyroIntegral
from .scale_fit import NotDetermined, attitude_increments, check_determined

ROTATION_SIGMA_MAX = np.radians(0.5)   # rad, 1-σ per axis: a slew about two axes gives arcminutes or better
OFFSET_SIGMA_MAX = 5e-3                # s, 1-σ of δt
MAX_ACCEL = np.radians(100.0)          # rad/s²: frames exposed under a harder angular acceleration are left out
SLEW_HINT = ("slew back and forth about at least two axes at several °/s; for the rotation to arcseconds, fast "
             "rest-to-rest slews about each axis (the miscal scenario, docs/FLATSAT.md §8)")


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
    gyro_map: np.ndarray | None = None   # M, camera ← gyro (3, 3): rotation and the gyro's scale/cross-axis errors
    rotation_sigma_gyro: np.ndarray | None = None  # 1-σ the same fit would reach with a noiseless camera (rad)

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
                  max_offset: float = 0.05, coarse_step: float = 0.5e-3, iterations: int = 15,
                  arw: float | None = None, max_accel: float = MAX_ACCEL) -> AlignFit:
    """Estimate ``R``, ``δt`` and ``b`` (see module docstring).

    The window increments are fitted with a general linear map ``M`` (camera ← gyro: rotation,
    and the gyro's scale-factor and cross-axis errors) rather than a rotation: with a rotation
    alone, a 3300 ppm scale error on a 4 °/s slew is a rate error the fit can only explain by
    shifting δt (several ms on the ``miscal`` ramps). For a given δt, ``M`` and ``M b`` follow by
    weighted least squares per camera axis, each window weighted by its noise — the camera's
    (estimated from the residuals) plus, with ``arw``, the gyro's N²·T over the window, so a
    window across a fast slew between two rests counts for what it is; windows whose gyro
    integral is not their rotation vector are left out
    (:meth:`~gyrostar.calibration.gyro_integral.GyroIntegral.rotation_windows`: turning more
    than 170°, where a rotation vector is ambiguous, or not about one fixed axis, as two
    fast slews about different axes in one window), and so are frames exposed while the
    gyro's rate changed faster than ``max_accel``
    (rad/s², over ±5 ms: the start of a fast slew — the exposure-averaged star position leaves
    the mid-exposure one by α·T²/24, and the gyro's low-pass lag is not a pure delay there;
    rate reversals of a few °/s² stay). δt minimises the profile likelihood Σ_a log RSS_a (each
    camera axis its own noise: roll is noisier), first on a ``coarse_step`` grid over
    ±``max_offset``, then by a bounded scalar search. ``R`` is the rotation factor of ``M``
    (polar decomposition), ``b = M⁻¹(M b)``. ``iterations`` is kept for callers; unused.

    With the gyro's angle random walk ``arw`` (N, rad/√s) the fit also reports
    ``rotation_sigma_gyro``: the 1-σ of the same windows if the camera were noiseless, each
    window's increment carrying only the gyro's N²·T — the limit this slew sets whatever the
    star tracker (about N / (ω⊥ √T_run) per axis)."""
    from scipy.optimize import minimize_scalar

    t_c = np.asarray(t_c, float)
    q_c = np.asarray(q_c, float)
    if q_c.shape != (len(t_c), 4) or len(t_c) < 3 * lag + 3:
        raise ConfigError(f"need (K, 4) attitudes at K ≥ {3 * lag + 3} epochs; got {q_c.shape} and {t_c.shape}")
    if np.any(np.diff(t_c) <= 0):
        raise ConfigError("camera epochs must increase strictly")
    gi = GyroIntegral(t_g, w_g)
    inside = (t_c - max_offset > gi.t[0]) & (t_c + max_offset < gi.t[-1])
    t_c, q_c = t_c[inside], q_c[inside]
    ta, tb = np.clip(t_c - 5e-3, gi.t[0], gi.t[-1]), np.clip(t_c + 5e-3, gi.t[0], gi.t[-1])
    calm = np.linalg.norm(gi.rate(tb) - gi.rate(ta), axis=1) <= max_accel * np.maximum(tb - ta, 1e-9)
    t_c, q_c = t_c[calm], q_c[calm]
    if len(t_c) < 3 * lag + 3:
        raise ConfigError(f"only {len(t_c)} camera epochs inside the gyro's span and under "
                          f"{np.degrees(max_accel):g} °/s² of angular acceleration; need {3 * lag + 3}")
    phi1 = attitude_increments(q_c)
    d0 = coarse_offset(gi, t_c, phi1, max_offset, coarse_step)
    idx = np.arange(0, len(t_c) - lag, lag)
    idx = idx[gi.rotation_windows(t_c[idx] - d0, t_c[idx + lag] - d0)]
    t0, t1 = t_c[idx], t_c[idx + lag]
    phi = _increments(q_c, idx, lag)
    span = t1 - t0
    n = len(idx)
    if n < 12:
        raise ConfigError(f"only {n} windows of {lag} frames: too few for the gyro map and the time offset")

    # each window's noise per camera axis: the camera's (two attitudes, c_a) and the gyro's
    # angle random walk over its span (N²·T); a window across a fast slew between two rests
    # spans seconds, the others a few frames. Weighted least squares with these variances
    # (c_a from the residuals); without ``arw`` every window weighs the same
    g = (arw * arw if arw else 0.0) * span
    wts = np.ones((3, n))

    def regress(dt):
        x = np.column_stack([gi.at(t1 - dt) - gi.at(t0 - dt), -span])
        coef = np.empty((4, 3))
        for a in range(3):                                  # φ_a ≈ x @ coef[:, a]: coef[:3] = Mᵀ, coef[3] = M b
            sw = np.sqrt(wts[a])
            coef[:, a] = np.linalg.lstsq(x * sw[:, None], phi[:, a] * sw, rcond=None)[0]
        res = phi - x @ coef
        return coef, res, x

    def noise_weights(res):
        c = np.maximum(np.mean(res ** 2 - g[:, None], axis=0), 0.01 * float(np.mean(g)))
        return 1.0 / (c[:, None] + g[None, :])

    if arw:
        for _ in range(2):
            wts = noise_weights(regress(d0)[1])

    def nll(dt):
        _, res, _ = regress(dt)
        return 0.5 * n * float(np.sum(np.log(np.maximum((wts.T * res ** 2).sum(axis=0), 1e-300))))

    grid = np.arange(-max_offset, max_offset + coarse_step / 2, coarse_step)
    costs = np.array([nll(d) for d in grid])
    k = int(np.argmin(costs))
    lo, hi = grid[max(k - 1, 0)], grid[min(k + 1, len(grid) - 1)]
    dt_off = float(minimize_scalar(nll, bounds=(lo, hi), method="bounded", options={"xatol": 1e-8}).x) \
        if hi > lo else float(grid[k])
    h = 0.1 * coarse_step
    curv = (nll(dt_off + h) - 2.0 * nll(dt_off) + nll(dt_off - h)) / (h * h)
    dt_sigma = float(1.0 / np.sqrt(curv)) if curv > 0 else float("nan")
    coef, res, x = regress(dt_off)
    m = coef[:3].T
    u, _, vt = np.linalg.svd(m)
    rot = u @ np.diag([1.0, 1.0, np.sign(np.linalg.det(u @ vt))]) @ vt
    bias = np.linalg.solve(m, coef[3])
    # rotation angles from the antisymmetric part of M: θ_x = (M₂₁ − M₁₂)/2, …; rows independent.
    # var of M[a, j] from row a's weighted fit, scaled by its χ²/dof
    var_m = np.empty((3, 3))
    var_g = np.empty((3, 3))
    for a in range(3):
        xw = x * wts[a][:, None]
        inv = np.linalg.inv(x.T @ xw)
        chi2 = float(np.sum(wts[a] * res[:, a] ** 2)) / max(n - 4, 1)
        var_m[a] = chi2 * np.diag(inv)[:3]
        var_g[a] = np.diag(inv @ (xw.T @ (xw * g[:, None])) @ inv)[:3]   # the gyro's share (sandwich)
    rot_sigma = _rotation_sigma(var_m)
    _check(rot_sigma, dt_sigma, m, var_m)
    rot_sigma_gyro = _rotation_sigma(var_g) if arw else None
    return AlignFit(rot, dt_off, bias, rot_sigma, dt_sigma, np.sqrt((res ** 2).mean(axis=0)), d0, n, m,
                    rot_sigma_gyro)


def _rotation_sigma(var: np.ndarray) -> np.ndarray:
    """1-σ of the rotation angles θ_x = (M₂₁ − M₁₂)/2, … from the variances of M's elements (rad)."""
    return 0.5 * np.sqrt(np.array([var[2, 1] + var[1, 2], var[0, 2] + var[2, 0], var[1, 0] + var[0, 1]]))


def _check(rot_sigma: np.ndarray, dt_sigma: float, m: np.ndarray, var_m: np.ndarray) -> None:
    """:class:`NotDetermined` unless the slew determines the rotation, δt and a gyro-like ``M``."""
    worst = float(np.max(rot_sigma))
    if not worst <= ROTATION_SIGMA_MAX:
        raise NotDetermined(f"gyro-camera alignment: the data do not determine it (the fit's 1σ reaches "
                            f"{np.degrees(worst):.3g}° on an axis, limit {np.degrees(ROTATION_SIGMA_MAX):g}°): "
                            f"{SLEW_HINT}; nothing written")
    if not dt_sigma <= OFFSET_SIGMA_MAX:
        raise NotDetermined(f"gyro-camera time offset: the data do not determine it (1σ {dt_sigma * 1e3:.3g} ms, "
                            f"limit {OFFSET_SIGMA_MAX * 1e3:g} ms): {SLEW_HINT}; nothing written")
    check_determined("gyro-camera alignment", m, np.sqrt(var_m), SLEW_HINT)


def _increments(q: np.ndarray, idx: np.ndarray, lag: int) -> np.ndarray:
    out = np.empty((len(idx), 3))
    for n, k in enumerate(idx):
        out[n] = attitude_increments(np.stack([q[k], q[k + lag]]))[0]
    return out
