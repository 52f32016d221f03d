"""Camera intrinsics from many identified star fields by robust bundle least squares.

Observation ``i``: star centroid ``uv_i`` (px, [column, row]) in field ``j(i)`` with catalog
direction ``r_i`` (ICRS unit vector). Model (:mod:`gyrostar.camera`, pinhole +
Brown–Conrady on normalised coordinates): ``uv_i = π(θ, A_j r_i)`` with intrinsics
``θ = [f_px, cx, cy, k1, k2, k3, p1, p2]`` and one attitude ``A_j`` (ICRS → body) per field.

Solver: Gauss–Newton with analytic Jacobians; each field's 3 attitude corrections are
eliminated by the Schur complement, so the normal equations are 8×8 whatever the number
of fields. Robustness: Huber weights (threshold ``huber_k`` × robust σ from the MAD of the
residual norms) and, after convergence, rejection of residuals above ``reject_k`` × σ
(misidentified stars), then a refit. When the table gives each observation's centroid σ
(``sigma``: the smeared-PSF fit's CRLB, which ``--export calib`` writes) every observation is
weighted by ``1/σ_eff²`` with ``σ_eff² = σ² + OBS_FLOOR_PX² + n·CLUSTER_FLOOR_PX²`` (n: the
observations of the same star in the same half-pixel cell — a star held at one pixel keeps
its fixed-pattern, blend and pixel-phase error in every frame, so a rest of a hundred frames
counts as about one measurement, not a hundred); the robust weights and the rejection then
act on residuals in units of σ_eff. Weak zero-mean priors on k2 and k3 (σ set by
``prior_k2``/``prior_k3``) keep the terms a narrow field cannot see bounded; where the data
determine them the priors are negligible.

Attitude updates are multiplicative: ``A_j ← R(δθ_j) A_j`` with ``R(φ) ≈ I − [φ×]``
(:func:`gyrostar.attitude.rotvec_to_quat`), body axes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import ConfigError

NAMES = ("f_px", "cx_px", "cy_px", "k1", "k2", "k3", "p1", "p2")
OBS_FLOOR_PX = 0.02       # px per axis: least error of one centroid (pixel response, blends, the PSF model)
CLUSTER_FLOOR_PX = 0.015  # px per axis: the error a star keeps at one pixel (measured at rest: 0.012-0.017 px)
CLUSTER_CELL_PX = 0.5     # px: observations of a star in one cell this size share that error


def fill_unknown_sigma(sigma: np.ndarray) -> np.ndarray | None:
    """Centroid σ (N,) px with each unknown one (NaN or ≤ 0: a plain CoG) set to the median
    of the usable ones; None when none is usable."""
    sg = np.asarray(sigma, dtype=float)
    ok = np.isfinite(sg) & (sg > 0)
    return np.where(ok, sg, np.median(sg[ok])) if ok.any() else None


@dataclass
class StarFields:
    """Identified stars: ``field`` (N,) int (any ids; renumbered 0..F-1 in order), ``uv`` (N, 2)
    px, ``ref`` (N, 3) ICRS; ``star`` (N,) int, optional: the catalogue star of each
    observation (a tracked star seen in many fields keeps its own centroid error: with it the
    fit's σ counts stars, not observations — see :func:`fit`); ``sigma`` (N,) px, optional: each
    centroid's 1σ per axis (NaN: unknown, the median is used)."""

    field: np.ndarray
    uv: np.ndarray
    ref: np.ndarray
    star: np.ndarray | None = None
    sigma: np.ndarray | None = None

    def __post_init__(self) -> None:
        self.field = np.asarray(self.field, dtype=np.int64)
        self.uv = np.asarray(self.uv, dtype=float)
        self.ref = np.asarray(self.ref, dtype=float)
        n = len(self.field)
        if self.uv.shape != (n, 2) or self.ref.shape != (n, 3):
            raise ConfigError(f"star table: field {self.field.shape}, uv {self.uv.shape}, ref {self.ref.shape} "
                              "must be (N,), (N, 2), (N, 3)")
        if n == 0 or not (np.all(np.isfinite(self.uv)) and np.all(np.isfinite(self.ref))):
            raise ConfigError("star table is empty or holds NaN/inf")
        if self.field.min() < 0:
            raise ConfigError("field ids must be non-negative")
        self.field = np.unique(self.field, return_inverse=True)[1].astype(np.int64)  # ids 0..F-1, no gaps
        counts = np.bincount(self.field)
        if np.any((counts > 0) & (counts < 3)):
            raise ConfigError("every field needs at least 3 identified stars")
        self.ref = self.ref / np.linalg.norm(self.ref, axis=1)[:, None]
        if self.star is not None:
            self.star = np.asarray(self.star, dtype=np.int64)
            if self.star.shape != (n,):
                raise ConfigError(f"star table: star ids {self.star.shape} must be ({n},)")
        if self.sigma is not None:
            sg = np.asarray(self.sigma, dtype=float)
            if sg.shape != (n,):
                raise ConfigError(f"star table: centroid sigmas {sg.shape} must be ({n},)")
            self.sigma = fill_unknown_sigma(sg)
            if self.sigma is None:
                raise ConfigError("star table: no centroid sigma is finite and positive")

    def weight_sigma(self, obs_floor: float = OBS_FLOOR_PX, cluster_floor: float = CLUSTER_FLOOR_PX) -> np.ndarray:
        """σ_eff (N,) px of every observation for the fit's weights (ones without ``sigma``):
        its own σ, the floor of one centroid, and the error it shares with the observations of
        the same star in the same ``CLUSTER_CELL_PX`` cell (with star ids only)."""
        n = len(self.field)
        if self.sigma is None:
            return np.ones(n)
        var = self.sigma ** 2 + obs_floor ** 2
        if self.star is not None and cluster_floor > 0:
            cell = np.floor(self.uv / CLUSTER_CELL_PX).astype(np.int64)
            key = np.column_stack([self.star, cell])
            _, inv, cnt = np.unique(key, axis=0, return_inverse=True, return_counts=True)
            var = var + cnt[inv.ravel()] * cluster_floor ** 2
        return np.sqrt(var)

    @property
    def n_fields(self) -> int:
        return int(self.field.max()) + 1


@dataclass
class IntrinsicsFit:
    theta: np.ndarray        # [f, cx, cy, k1, k2, k3, p1, p2]
    sigma: np.ndarray        # 1-σ of theta (0 where fixed): per star when the table names its stars
    sigma_iid: np.ndarray    # 1-σ as if every observation's error were independent
    attitudes: np.ndarray    # (F, 3, 3) ICRS → body
    residuals: np.ndarray    # (N, 2) px, observed − model
    inlier: np.ndarray       # (N,) bool
    rms_px: float            # inlier residual RMS per axis
    iterations: int

    def params(self, width: int, height: int) -> np.ndarray:
        """Parameter vector in :mod:`gyrostar.camera` layout."""
        return np.array([*self.theta, width, height], dtype=float)


def project(theta: np.ndarray, s: np.ndarray, jac: bool = False):
    """Pixel coordinates of body vectors ``s`` (N, 3); with ``jac`` also ∂uv/∂θ (N, 2, 8)
    and ∂uv/∂s (N, 2, 3)."""
    f, cx, cy, k1, k2, k3, p1, p2 = theta
    x = s[:, 0] / s[:, 2]
    y = s[:, 1] / s[:, 2]
    r2 = x * x + y * y
    rad = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    xd = x * rad + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
    yd = y * rad + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    uv = np.column_stack([cx + f * xd, cy + f * yd])
    if not jac:
        return uv
    n = len(s)
    jt = np.zeros((n, 2, 8))
    jt[:, 0, 0], jt[:, 1, 0] = xd, yd
    jt[:, 0, 1] = 1.0
    jt[:, 1, 2] = 1.0
    for col, pw in ((3, r2), (4, r2 * r2), (5, r2 * r2 * r2)):
        jt[:, 0, col], jt[:, 1, col] = f * x * pw, f * y * pw
    jt[:, 0, 6], jt[:, 1, 6] = f * 2 * x * y, f * (r2 + 2 * y * y)
    jt[:, 0, 7], jt[:, 1, 7] = f * (r2 + 2 * x * x), f * 2 * x * y
    dr = k1 + r2 * (2 * k2 + 3 * k3 * r2)
    dxx = rad + 2 * x * x * dr + 2 * p1 * y + 6 * p2 * x
    dxy = 2 * x * y * dr + 2 * p1 * x + 2 * p2 * y
    dyx = 2 * x * y * dr + 2 * p1 * x + 2 * p2 * y
    dyy = rad + 2 * y * y * dr + 6 * p1 * y + 2 * p2 * x
    iz = 1.0 / s[:, 2]
    # ∂(x, y)/∂s
    dn = np.zeros((n, 2, 3))
    dn[:, 0, 0] = iz
    dn[:, 0, 2] = -x * iz
    dn[:, 1, 1] = iz
    dn[:, 1, 2] = -y * iz
    dd = np.empty((n, 2, 2))
    dd[:, 0, 0], dd[:, 0, 1], dd[:, 1, 0], dd[:, 1, 1] = dxx, dxy, dyx, dyy
    js = f * np.einsum("nab,nbc->nac", dd, dn)
    return uv, jt, js


def _cross_mat(s: np.ndarray) -> np.ndarray:
    m = np.zeros((len(s), 3, 3))
    m[:, 0, 1], m[:, 0, 2] = -s[:, 2], s[:, 1]
    m[:, 1, 0], m[:, 1, 2] = s[:, 2], -s[:, 0]
    m[:, 2, 0], m[:, 2, 1] = -s[:, 1], s[:, 0]
    return m


def rotvec_dcm(phi: np.ndarray) -> np.ndarray:
    """Batch ``A(δq(φ))`` (F, 3, 3) for rotation vectors (F, 3), ≈ I − [φ×]."""
    ang = np.linalg.norm(phi, axis=1)
    k = np.where(ang > 1e-12, ang, 1.0)
    axis = phi / k[:, None]
    c, s = np.cos(ang), np.sin(ang)
    kx = _cross_mat(axis)
    eye = np.eye(3)[None]
    outer = np.einsum("ni,nj->nij", axis, axis)
    return c[:, None, None] * eye + (1 - c)[:, None, None] * outer - s[:, None, None] * kx


def initial_attitudes(stars: StarFields, theta: np.ndarray) -> np.ndarray:
    """Per-field attitude (QUEST, :mod:`gyrostar.core.quest`) from the directions the
    intrinsics ``theta`` give the centroids."""
    from ..attitude import quat_to_dcm
    from ..camera import unproject_many
    from ..core.quest import quest

    params = np.array([*theta, 1e9, 1e9])
    body = unproject_many(params, np.ascontiguousarray(stars.uv))
    out = np.zeros((stars.n_fields, 3, 3))
    for j in range(stars.n_fields):
        sel = stars.field == j
        if not sel.any():
            out[j] = np.eye(3)
            continue
        q, _ = quest(np.ascontiguousarray(body[sel]), np.ascontiguousarray(stars.ref[sel]), np.ones(sel.sum()))
        out[j] = quat_to_dcm(q)
    return out


def fit(stars: StarFields, theta0: np.ndarray, free: np.ndarray | None = None, attitudes=None,
        huber_k: float = 2.5, reject_k: float = 5.0, prior_k2: float = 100.0, prior_k3: float = 1e4,
        max_iter: int = 30, tol: float = 1e-10) -> IntrinsicsFit:
    """Robust bundle fit of the intrinsics (``free`` mask over :data:`NAMES`; default all)
    and the per-field attitudes, starting from ``theta0``."""
    theta = np.asarray(theta0, float).copy()
    free = np.ones(8, bool) if free is None else np.asarray(free, bool)
    att = initial_attitudes(stars, theta) if attitudes is None else np.array(attitudes, float)
    nf = stars.n_fields
    fid = stars.field
    inlier = np.ones(len(fid), bool)
    osig = stars.weight_sigma()          # px; ones when the table has no centroid σ
    prior = np.zeros(8)
    prior[4], prior[5] = 1.0 / prior_k2**2, 1.0 / prior_k3**2
    iterations = 0
    for stage in range(2):
        for _ in range(max_iter):
            iterations += 1
            s = np.einsum("nij,nj->ni", att[fid], stars.ref)
            pred, jt, js = project(theta, s, jac=True)
            res = stars.uv - pred
            ja = np.einsum("nab,nbc->nac", js, _cross_mat(s))
            norm = np.linalg.norm(res, axis=1) / osig
            sig = 1.4826 * np.median(norm[inlier]) / np.sqrt(np.log(4.0)) + 1e-12  # Rayleigh median → σ
            w = np.where(norm <= huber_k * sig, 1.0, huber_k * sig / np.maximum(norm, 1e-300)) * inlier / osig ** 2
            jt = jt[:, :, free]
            # the data term is in units of σ_eff (px without a table σ): the prior, a statement about
            # the parameter, is scaled to them by the residual variance (σ_eff units: ~1; px: ~σ²)
            pw = prior[free] * sig ** 2
            u = np.einsum("n,nai,naj->ij", w, jt, jt) + np.diag(pw)
            bt = np.einsum("n,nai,na->i", w, jt, res) - pw * theta[free]
            vj = np.zeros((nf, 3, 3))
            np.add.at(vj, fid, np.einsum("n,nai,naj->nij", w, ja, ja))
            wj = np.zeros((nf, jt.shape[2], 3))
            np.add.at(wj, fid, np.einsum("n,nai,naj->nij", w, jt, ja))
            ba = np.zeros((nf, 3))
            np.add.at(ba, fid, np.einsum("n,nai,na->ni", w, ja, res))
            vj += np.eye(3)[None] * 1e-12 * np.trace(vj, axis1=1, axis2=2)[:, None, None].clip(1e-30)
            vinv = np.linalg.inv(vj)
            wv = np.einsum("fij,fjk->fik", wj, vinv)
            red = u - np.einsum("fij,fkj->ik", wv, wj)
            rhs = bt - np.einsum("fij,fj->i", wv, ba)
            d_int = np.linalg.solve(red, rhs) if red.size else np.zeros(0)
            d_att = np.einsum("fij,fj->fi", vinv, ba - np.einsum("fij,i->fj", wj, d_int))
            theta[free] += d_int
            att = np.einsum("fij,fjk->fik", rotvec_dcm(d_att), att)
            step = np.abs(d_int) / np.maximum(np.abs(theta[free]), 1e-3) if d_int.size else np.zeros(1)
            if (step.max(initial=0.0) < tol) and np.abs(d_att).max() < 1e-11:
                break
        if stage == 0 and reject_k > 0:
            s = np.einsum("nij,nj->ni", att[fid], stars.ref)
            norm = np.linalg.norm(stars.uv - project(theta, s), axis=1) / osig
            sig = 1.4826 * np.median(norm) / np.sqrt(np.log(4.0))
            inlier = norm <= reject_k * sig
        else:
            break
    s = np.einsum("nij,nj->ni", att[fid], stars.ref)
    res = stars.uv - project(theta, s)
    dof = max(2 * inlier.sum() - free.sum() - 3 * nf, 1)
    s2 = float(((res[inlier] / osig[inlier, None]) ** 2).sum() / dof)   # px² without σ, else ~1
    sigma = np.zeros(8)
    sigma_iid = np.zeros(8)
    if free.any():
        red_inv = np.linalg.inv(red)
        sigma_iid[free] = np.sqrt(np.clip(np.diag(red_inv * s2), 0, None))
        sigma[:] = sigma_iid
        if stars.star is not None:
            sigma[free] = np.sqrt(np.clip(np.diag(_per_star_cov(stars, theta, att, free, inlier, w, red_inv)), 0, None))
    rms = float(np.sqrt((res[inlier] ** 2).mean()))
    return IntrinsicsFit(theta, sigma, sigma_iid, att, res, inlier, rms, iterations)


def _per_star_cov(stars: StarFields, theta, att, free, inlier, w, red_inv) -> np.ndarray:
    """Covariance of the free intrinsics with the observations of one star as one cluster
    (sandwich estimator, attitudes profiled out): ``R⁻¹ (Σ_g S_g S_gᵀ) R⁻¹ · G/(G−1)`` where
    ``S_g`` sums over star g's observations the score ``w J̃ᵀ r`` of the reduced problem
    (``J̃ = J_θ − J_a V_f⁻¹ W_fᵀ``, f the observation's field) and ``R`` is its normal matrix.
    A star that keeps its centroid error in every field counts once, not once per field."""
    fid = stars.field
    nf = stars.n_fields
    s = np.einsum("nij,nj->ni", att[fid], stars.ref)
    pred, jt, js = project(theta, s, jac=True)
    res = stars.uv - pred
    ja = np.einsum("nab,nbc->nac", js, _cross_mat(s))
    jt = jt[:, :, free]
    wi = w * inlier
    vj = np.zeros((nf, 3, 3))
    np.add.at(vj, fid, np.einsum("n,nai,naj->nij", wi, ja, ja))
    wj = np.zeros((nf, jt.shape[2], 3))
    np.add.at(wj, fid, np.einsum("n,nai,naj->nij", wi, jt, ja))
    vj += np.eye(3)[None] * 1e-12 * np.trace(vj, axis1=1, axis2=2)[:, None, None].clip(1e-30)
    proj = np.einsum("fij,fkj->fik", np.linalg.inv(vj), wj)          # V_f⁻¹ W_fᵀ: (F, 3, p)
    jr = jt - np.einsum("naj,njk->nak", ja, proj[fid])                # J̃ (N, 2, p)
    score = np.einsum("n,nai,na->ni", wi, jr, res)                    # (N, p)
    groups = np.unique(stars.star[inlier], return_inverse=True)[1]
    sg = np.zeros((groups.max() + 1 if len(groups) else 0, score.shape[1]))
    np.add.at(sg, groups, score[inlier])
    g = len(sg)
    meat = sg.T @ sg * (g / (g - 1) if g > 1 else 1.0)
    return red_inv @ meat @ red_inv


def model_difference(params_a: np.ndarray, params_b: np.ndarray, n_grid: int = 21) -> tuple[float, float]:
    """RMS and max (px) of the pixel difference between two camera models over an
    ``n_grid``² grid covering the sensor, after the rotation that best aligns them (an
    attitude is re-estimated in use, so a common rotation is not an error). Parameter
    vectors in :mod:`gyrostar.camera` layout (``[f, cx, cy, k1, k2, k3, p1, p2, w, h]``)."""
    from ..camera import unproject_many

    w, h = params_b[8], params_b[9]
    g = np.linspace(0.0, 1.0, n_grid)
    uu, vv = np.meshgrid(-0.5 + g * w, -0.5 + g * h)
    uv = np.column_stack([uu.ravel(), vv.ravel()])
    d = unproject_many(np.asarray(params_b, float), uv)
    theta = np.asarray(params_a[:8], float)
    rot = np.eye(3)
    for _ in range(10):
        s = d @ rot.T
        pred, _, js = project(theta, s, jac=True)
        res = uv - pred
        ja = np.einsum("nab,nbc->nac", js, _cross_mat(s)).reshape(-1, 3)
        delta, *_ = np.linalg.lstsq(ja, res.ravel(), rcond=None)
        rot = rotvec_dcm(delta[None])[0] @ rot
    err = np.linalg.norm(uv - project(theta, d @ rot.T), axis=1)
    return float(np.sqrt((err**2).mean())), float(err.max())
