"""Estimation-core speed: each numba kernel against a plain-numpy implementation of the same step.

The numba figure is measured inside a compiled loop (how the 400/100 Hz loop calls it:
no Python call per sample); the numpy baseline is the same algorithm written with numpy
arrays and called from Python, as one would without numba. Same inputs, same run.

* ``ekf_predict`` — one 400 Hz spot-EKF predict (pinhole model, Φ P Φᵀ + Q, 5 states).
* ``ekf_update`` — one image update (2-D measurement, χ² gate, Joseph form).
* ``ekf_predict_plus_update`` — the two together, per star (target ≤ 2 µs).
* ``window_build`` — trajectory window (6×6 squares along a 5 °/s-per-axis, 10 ms path) to row spans.
* ``centroid_cog`` — thresholded CoG on that window (~110 px).
* ``centroid_smear_fit`` — the default EKF centroid: smeared-PSF least-squares fit.
* ``quest`` — QUEST with covariance, 10 stars.
* ``joint_update_10`` — joint filter image update, 10 stars (23 states; target ≤ 30 µs).
* ``joint_predict_10`` — joint filter 400 Hz predict, 10 stars.
"""

from __future__ import annotations

import math
import statistics
import time

import numpy as np
from gyrostar.core.centroid import MERGE_PX, cog, smear_fit
from gyrostar.core.joint_filter import joint_add_star, joint_init, joint_predict, joint_update, joint_workspace
from gyrostar.core.motion import MODEL_PINHOLE, predict_trajectory, step_spot
from gyrostar.core.quest import quest
from gyrostar.core.spot_ekf import CHI2_2DOF_999, spot_ekf_init, spot_ekf_predict, spot_ekf_update
from gyrostar.core.windows import trajectory_window
from numba import njit
from scipy.special import erf

F_PX = 100e-3 / 15e-6
DT = 1 / 400
SIG_RATE = math.radians(0.014) * math.sqrt(200.0)


def _median_us(fn, repeat: int) -> float:
    fn()
    out = []
    for _ in range(repeat):
        out.append(fn())
    return statistics.median(out)


def _py_us(fn, repeat: int, inner: int) -> float:
    fn()
    out = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        for _ in range(inner):
            fn()
        out.append((time.perf_counter() - t0) / inner * 1e6)
    return statistics.median(out)


# ---- numba loops (one compiled call runs n kernel calls) ---------------------------------------
@njit  # no cache: this module is loaded from a path by the bench runner
def _loop_predict(X, P, w, n):
    for _ in range(n):
        spot_ekf_predict(X, P, w, DT, F_PX, SIG_RATE, 1e-7, MODEL_PINHOLE)


@njit  # no cache: this module is loaded from a path by the bench runner
def _loop_update(X, P, n):
    for _ in range(n):
        spot_ekf_update(X, P, X[0] + 0.05, X[1] - 0.05, 0.01, 0.01, CHI2_2DOF_999)
        P[0, 0] += 0.01  # keep the covariance from collapsing over the repetitions
        P[1, 1] += 0.01


@njit  # no cache: this module is loaded from a path by the bench runner
def _loop_predict_update(X, P, w, n):
    for _ in range(n):
        spot_ekf_predict(X, P, w, DT, F_PX, SIG_RATE, 1e-7, MODEL_PINHOLE)
        spot_ekf_update(X, P, X[0] + 0.05, X[1] - 0.05, 0.01, 0.01, CHI2_2DOF_999)


@njit  # no cache: this module is loaded from a path by the bench runner
def _loop_window(traj, n, k=6):
    c = 0
    for _ in range(n):
        c += trajectory_window(traj, k, 1024, 1024, 0).shape[0]
    return c


@njit  # no cache: this module is loaded from a path by the bench runner
def _loop_cog(spans, vals, n):
    s = 0.0
    for _ in range(n):
        s += cog(spans, vals, 20.0, 30.0)[0]
    return s


@njit  # no cache: this module is loaded from a path by the bench runner
def _loop_fit(spans, vals, u0, v0, offs, n):
    s = 0.0
    for _ in range(n):
        s += smear_fit(spans, vals, 20.0, u0, v0, offs, 0.85, 12.0, 5.0, 10, 1e-3)[0]
    return s


@njit  # no cache: this module is loaded from a path by the bench runner
def _loop_quest(b, r, w, n):
    s = 0.0
    for _ in range(n):
        s += quest(b, r, w)[0][3]
    return s


@njit  # no cache: this module is loaded from a path by the bench runner
def _loop_joint_update(X, P, act, z, rv, acc, nis, n):
    for _ in range(n):
        joint_update(X, P, act, z, rv, CHI2_2DOF_999, acc, nis)
        for i in range(20):
            P[i, i] += 0.01


@njit  # no cache: this module is loaded from a path by the bench runner
def _loop_joint_predict(X, P, act, w, work, n):
    for _ in range(n):
        joint_predict(X, P, act, w, DT, F_PX, SIG_RATE, 1e-7, MODEL_PINHOLE, work)


def _timed(loop, n, *args) -> float:
    t0 = time.perf_counter()
    loop(*args, n)
    return (time.perf_counter() - t0) / n * 1e6


# ---- plain numpy implementations of the same steps ---------------------------------------------
def np_predict(X, P, w):
    x, y = X[0], X[1]
    u = w - X[2:]
    f = F_PX
    G = np.array([[x * y / f, -f - x * x / f, y], [f + y * y / f, -x * y / f, -x]])
    phi = np.eye(5)
    phi[0, 0] += -(2 * x * u[1] - y * u[0]) / f * DT
    phi[0, 1] = (u[2] + x * u[0] / f) * DT
    phi[1, 0] = (-u[2] - y * u[1] / f) * DT
    phi[1, 1] += -(x * u[1] - 2 * y * u[0]) / f * DT
    phi[:2, 2:] = -G * DT
    # exact rotation step (Rodrigues) of s = (x, y, f)
    p = -u * DT
    th = np.linalg.norm(p)
    s = np.array([x, y, f])
    c = np.cross(p, s)
    n = s + np.sin(th) / th * c + (1 - np.cos(th)) / th ** 2 * np.cross(p, c)
    X[0], X[1] = f * n[0] / n[2], f * n[1] / n[2]
    Q = np.zeros((5, 5))
    Q[:2, :2] = SIG_RATE ** 2 * DT ** 2 * G @ G.T
    Q[2:, 2:] = np.eye(3) * 1e-14 * DT
    P[:] = phi @ P @ phi.T + Q


H = np.hstack([np.eye(2), np.zeros((2, 3))])


def np_update(X, P, z, R):
    nu = z - H @ X
    S = H @ P @ H.T + R
    Si = np.linalg.inv(S)
    if nu @ Si @ nu > CHI2_2DOF_999:
        return False
    K = P @ H.T @ Si
    X += K @ nu
    A = np.eye(5) - K @ H
    P[:] = A @ P @ A.T + K @ R @ K.T
    return True


def np_window(traj, k, n_rows, n_cols):
    seg = np.diff(traj, axis=0)
    ns = np.maximum(1, np.ceil(np.abs(seg).max(axis=1) / 0.5)).astype(int)
    pts = np.concatenate([traj[i] + np.arange(ns[i])[:, None] / ns[i] * seg[i] for i in range(len(seg))]
                         + [traj[-1:]])
    org = np.floor(pts - (k - 1) / 2 + 0.5).astype(int)
    c0, r0 = org.min(axis=0)
    c1, r1 = org.max(axis=0) + k
    mask = np.zeros((r1 - r0, c1 - c0), bool)
    for (c, r) in org:
        mask[r - r0:r - r0 + k, c - c0:c - c0 + k] = True
    rows = []
    for i in range(mask.shape[0]):
        d = np.diff(np.concatenate([[0], mask[i].astype(np.int8), [0]]))
        starts, stops = np.flatnonzero(d == 1), np.flatnonzero(d == -1)
        for a, b in zip(starts, stops):
            rows.append((0, r0 + i, c0 + a, c0 + b))
    sp = np.array(rows, np.int32)
    keep = (sp[:, 1] >= 0) & (sp[:, 1] < n_rows)
    sp = sp[keep]
    sp[:, 2] = np.clip(sp[:, 2], 0, n_cols)
    sp[:, 3] = np.clip(sp[:, 3], 0, n_cols)
    return sp


def _span_coords(spans):
    rows = np.repeat(spans[:, 1], spans[:, 3] - spans[:, 2])
    cols = np.concatenate([np.arange(a, b) for a, b in spans[:, 2:]])
    return cols, rows


def np_cog(spans, vals, bg, thr):
    cols, rows = _span_coords(spans)
    m = vals > thr
    w = vals[m] - bg
    return (w @ cols[m]) / w.sum(), (w @ rows[m]) / w.sum()


def _np_merge(offs):
    """The path points grouped as smear_fit groups them (runs within MERGE_PX of their first)."""
    groups, j = [], 0
    while j < len(offs):
        k = j + 1
        while k < len(offs) and np.all(np.abs(offs[k] - offs[j]) <= MERGE_PX):
            k += 1
        groups.append((offs[j:k].mean(axis=0), (k - j) / len(offs)))
        j = k
    return np.array([g[0] for g in groups]), np.array([g[1] for g in groups])


def np_smear_fit(spans, vals, bg, u0, v0, offs, sig, noise_var, e_per_dn, n_iter, tol):
    cols, rows = _span_coords(spans)
    offs, gw = _np_merge(offs)
    d = vals - bg
    wgt = 1.0 / (noise_var + np.maximum(d, 0) / e_per_dn)
    flux = max(d.sum(), 1.0)
    u, v = u0, v0
    k = 1 / (math.sqrt(2) * sig)
    pdf = 1 / (sig * math.sqrt(2 * math.pi))
    for _ in range(n_iter):
        cu = u + offs[:, 0][:, None]
        cv = v + offs[:, 1][:, None]
        lo_c = cols[None] - 0.5 - cu
        lo_r = rows[None] - 0.5 - cv
        ex = 0.5 * (erf((lo_c + 1) * k) - erf(lo_c * k))
        ey = 0.5 * (erf((lo_r + 1) * k) - erf(lo_r * k))
        dx = pdf * (np.exp(-0.5 * (lo_c / sig) ** 2) - np.exp(-0.5 * ((lo_c + 1) / sig) ** 2))
        dy = pdf * (np.exp(-0.5 * (lo_r / sig) ** 2) - np.exp(-0.5 * ((lo_r + 1) / sig) ** 2))
        t = gw @ (ex * ey)
        J = np.column_stack([flux * (gw @ (dx * ey)), flux * (gw @ (ex * dy)), t])
        r = d - flux * t
        A = J.T @ (J * wgt[:, None])
        step = np.linalg.solve(A, J.T @ (wgt * r))
        u += np.clip(step[0], -1, 1)
        v += np.clip(step[1], -1, 1)
        flux += step[2]
        if abs(step[0]) + abs(step[1]) < tol:
            break
    return u, v


def np_quest(b, r, w):
    B = (w[:, None] * b).T @ r
    S = B + B.T
    sigma = np.trace(B)
    z = np.array([B[1, 2] - B[2, 1], B[2, 0] - B[0, 2], B[0, 1] - B[1, 0]])
    kappa = np.trace(np.linalg.inv(S) * np.linalg.det(S)) if abs(np.linalg.det(S)) > 0 else 0.0
    delta = np.linalg.det(S)
    a = sigma ** 2 - kappa
    bb = sigma ** 2 + z @ z
    c = delta + z @ S @ z
    d = z @ S @ S @ z
    lam = w.sum()
    for _ in range(50):
        f = lam ** 4 - (a + bb) * lam ** 2 - c * lam + (a * bb + c * sigma - d)
        step = f / (4 * lam ** 3 - 2 * (a + bb) * lam - c)
        lam -= step
        if abs(step) < 1e-15 * lam:
            break
    alpha = lam ** 2 - sigma ** 2 + kappa
    x = (alpha * np.eye(3) + (lam - sigma) * S + S @ S) @ z
    q = np.append(x, (lam + sigma) * alpha - delta)
    q /= np.linalg.norm(q)
    info = w.sum() * np.eye(3) - (w[:, None] * b).T @ b
    return q, np.linalg.inv(info)


def np_joint_update(X, P, z, rv):
    n = z.shape[0]
    N = X.shape[0]
    Hm = np.zeros((2 * n, N))
    Hm[:, :2 * n] = np.eye(2 * n)
    R = np.diag(rv.ravel())
    nu = z.ravel() - X[:2 * n]
    S = Hm @ P @ Hm.T + R
    K = P @ Hm.T @ np.linalg.inv(S)
    X += K @ nu
    P[:] = (np.eye(N) - K @ Hm) @ P


def np_joint_predict(X, P, w, n):
    N = X.shape[0]
    Phi = np.eye(N)
    Gs = []
    for s in range(n):
        x, y = X[2 * s], X[2 * s + 1]
        u = w - X[-3:]
        f = F_PX
        G = np.array([[x * y / f, -f - x * x / f, y], [f + y * y / f, -x * y / f, -x]])
        Phi[2 * s, 2 * s] += -(2 * x * u[1] - y * u[0]) / f * DT
        Phi[2 * s, 2 * s + 1] = (u[2] + x * u[0] / f) * DT
        Phi[2 * s + 1, 2 * s] = (-u[2] - y * u[1] / f) * DT
        Phi[2 * s + 1, 2 * s + 1] += -(x * u[1] - 2 * y * u[0]) / f * DT
        Phi[2 * s:2 * s + 2, -3:] = -G * DT
        X[2 * s], X[2 * s + 1] = step_spot(x, y, u[0], u[1], u[2], DT, f, MODEL_PINHOLE)
        Gs.append(G)
    Gall = np.vstack(Gs)
    Q = np.zeros((N, N))
    Q[:2 * n, :2 * n] = SIG_RATE ** 2 * DT ** 2 * Gall @ Gall.T
    Q[-3:, -3:] = np.eye(3) * 1e-14 * DT
    P[:] = Phi @ P @ Phi.T + Q


# ---- the cases ----------------------------------------------------------------------------------
def _case(us, base, note):
    return {"us": us, "baseline_us": base, "ratio": base / us, "note": note}


def run(quick: bool) -> dict:
    rep = 3 if quick else 7
    n_fast = 20000 if quick else 100000
    rng = np.random.default_rng(0)
    out = {}
    w = np.radians([5.0, 5.0, 5.0])

    X, P = spot_ekf_init(200.0, -150.0, np.zeros(3), 0.3, 1e-3)
    t_nb = _median_us(lambda: _timed(_loop_predict, n_fast, X, P, w), rep)
    X2, P2 = spot_ekf_init(200.0, -150.0, np.zeros(3), 0.3, 1e-3)
    t_np = _py_us(lambda: np_predict(X2, P2, w), rep, 2000)
    out["ekf_predict"] = _case(t_nb, t_np, "spot EKF predict, pinhole, 5 states")

    X, P = spot_ekf_init(200.0, -150.0, np.zeros(3), 0.3, 1e-3)
    t_nb = _median_us(lambda: _timed(_loop_update, n_fast, X, P), rep)
    X2, P2 = spot_ekf_init(200.0, -150.0, np.zeros(3), 0.3, 1e-3)
    z = np.array([200.05, -150.05])
    R = np.eye(2) * 0.01
    t_np = _py_us(lambda: np_update(X2, P2, z, R), rep, 2000)
    out["ekf_update"] = _case(t_nb, t_np, "spot EKF update, χ² gate, Joseph")

    X, P = spot_ekf_init(200.0, -150.0, np.zeros(3), 0.3, 1e-3)
    t_nb = _median_us(lambda: _timed(_loop_predict_update, n_fast, X, P, w), rep)
    t_np = out["ekf_predict"]["baseline_us"] + out["ekf_update"]["baseline_us"]
    out["ekf_predict_plus_update"] = _case(t_nb, t_np, "per star; target ≤ 2 µs")

    traj = predict_trajectory(300.0, 200.0, np.tile(w, (4, 1)), DT, np.zeros(3), F_PX, MODEL_PINHOLE, 2)
    traj += 511.5
    spans = trajectory_window(traj, 6, 1024, 1024, 0)
    np.testing.assert_array_equal(np_window(traj, 6, 1024, 1024), spans)
    t_nb = _median_us(lambda: _timed(_loop_window, n_fast // 10, traj), rep)
    t_np = _py_us(lambda: np_window(traj, 6, 1024, 1024), rep, 300)
    out["window_build"] = _case(t_nb, t_np, f"{spans.shape[0]} spans, {int(np.sum(spans[:, 3] - spans[:, 2]))} px")
    # a slew: 20 °/s over a 10 ms exposure and its 2.5 ms lag (~29 px of trail), the window
    # widened to the loop's cap of 40 px by the attitude's uncertainty
    w_slew = np.array([0.0, 0.0, math.radians(20.0)]) + np.array([math.radians(14.0), math.radians(-14.0), 0.0])
    traj_s = predict_trajectory(300.0, 200.0, np.tile(w_slew, (5, 1)), DT, np.zeros(3), F_PX, MODEL_PINHOLE, 24)
    traj_s += 511.5
    spans_s = trajectory_window(traj_s, 40, 1024, 1024, 0)
    np.testing.assert_array_equal(np_window(traj_s, 40, 1024, 1024), spans_s)
    t_nb = _median_us(lambda: _timed(_loop_window, n_fast // 100, traj_s, 40), rep)
    t_np = _py_us(lambda: np_window(traj_s, 40, 1024, 1024), rep, 30)
    trail = float(np.hypot(*(traj_s[-1] - traj_s[0])))
    out["window_build_slew"] = _case(t_nb, t_np, f"{trail:.0f} px trail, k 40: {spans_s.shape[0]} spans, "
                                                 f"{int(np.sum(spans_s[:, 3] - spans_s[:, 2]))} px")

    npx = int(np.sum(spans[:, 3] - spans[:, 2]))
    centre = traj.mean(axis=0)
    cols, rows = _span_coords(spans)
    clean = np.zeros(npx)
    for p in traj:
        clean += 2100 / 5 / len(traj) * np.exp(-((cols - p[0]) ** 2 + (rows - p[1]) ** 2) / (2 * 0.85 ** 2)) / (
            2 * np.pi * 0.85 ** 2)
    vals = clean + 20.0 + rng.normal(0, 3.4, npx)
    t_nb = _median_us(lambda: _timed(_loop_cog, n_fast, spans, vals), rep)
    t_np = _py_us(lambda: np_cog(spans, vals, 20.0, 30.0), rep, 2000)
    out["centroid_cog"] = _case(t_nb, t_np, f"{npx}-px window")

    offs = np.ascontiguousarray(traj - centre)
    a = smear_fit(spans, vals, 20.0, centre[0], centre[1], offs, 0.85, 12.0, 5.0, 10, 1e-3)
    b = np_smear_fit(spans, vals, 20.0, centre[0], centre[1], offs, 0.85, 12.0, 5.0, 10, 1e-3)
    assert abs(a[0] - b[0]) < 1e-6 and abs(a[1] - b[1]) < 1e-6
    t_nb = _median_us(lambda: _timed(_loop_fit, 500 if quick else 2000, spans, vals, centre[0], centre[1], offs), rep)
    t_np = _py_us(lambda: np_smear_fit(spans, vals, 20.0, centre[0], centre[1], offs, 0.85, 12.0, 5.0, 10, 1e-3),
                  rep, 50)
    out["centroid_smear_fit"] = _case(t_nb, t_np, f"{npx} px, {len(offs)} path points")

    ref = rng.normal(size=(10, 3))
    ref /= np.linalg.norm(ref, axis=1)[:, None]
    body = ref @ np.array([[0.36, 0.48, -0.8], [-0.8, 0.6, 0.0], [0.48, 0.64, 0.6]]).T
    wq = np.full(10, 1e8)
    t_nb = _median_us(lambda: _timed(_loop_quest, n_fast // 10, body, ref, wq), rep)
    t_np = _py_us(lambda: np_quest(body, ref, wq), rep, 1000)
    out["quest"] = _case(t_nb, t_np,
                         "10 stars, with covariance (numba: one λ, the best of 4 sequential-rotation candidates)")

    n = 10
    X, P, act = joint_init(n, np.zeros(3), 1e-3)
    for i in range(n):
        joint_add_star(X, P, act, i, rng.uniform(-400, 400), rng.uniform(-400, 400), 0.01)
    z = X[:2 * n].reshape(n, 2) + 0.05
    rv = np.full((n, 2), 0.01)
    acc = np.zeros(n, np.uint8)
    nis = np.zeros(n)
    Xb, Pb = X.copy(), P.copy()
    t_nb = _median_us(lambda: _timed(_loop_joint_update, n_fast // 10, X, P, act, z, rv, acc, nis), rep)
    t_np = _py_us(lambda: np_joint_update(Xb, Pb, z, rv), rep, 1000)
    out["joint_update_10"] = _case(t_nb, t_np, "23 states, per image; target ≤ 30 µs")
    work = joint_workspace(n)
    Xb, Pb = X.copy(), P.copy()
    t_nb = _median_us(lambda: _timed(_loop_joint_predict, n_fast // 10, X, P, act, w, work), rep)
    t_np = _py_us(lambda: np_joint_predict(Xb, Pb, w, n), rep, 300)
    out["joint_predict_10"] = _case(t_nb, t_np, "23 states, per 400 Hz sample")
    return out
