"""Spot motion on the image plane and trajectory prediction from gyro rates (paper 000 §2).

Image-plane coordinates ``(x, y)`` are pixels from the principal point (x along columns,
y along rows), ``f_px = F / a`` is the focal length in pixels, ``ω`` the body rate (rad/s,
body = camera axes, ``gyrostar.attitude``). A fixed star's direction ``s ∝ (x, y, f)`` moves
as ``ṡ = −ω × s``, which gives

* first order (paper eq. 2.1, roll sign per our axes):
  ``V_x = ω_z·y − ω_y·f``,  ``V_y = −ω_z·x + ω_x·f``
* full pinhole (adds the off-axis terms, ~x²/f² of the rate term):
  ``V_x = ω_z·y − ω_y·f − (x²·ω_y − x·y·ω_x)/f``,
  ``V_y = −ω_z·x + ω_x·f − (x·y·ω_y − y²·ω_x)/f``

``MODEL_FIRST_ORDER`` (0) is the paper's model; ``MODEL_PINHOLE`` (1) steps the exact
projection of a rotation under constant ω over each gyro interval.
"""

from __future__ import annotations

import numpy as np
from numba import njit

MODEL_FIRST_ORDER = 0
MODEL_PINHOLE = 1


@njit(cache=True)
def spot_velocity(x, y, omega, f_px, model):
    """Image-plane velocity (px/s) of a spot at (x, y) px under body rate ``omega`` (rad/s)."""
    vx = omega[2] * y - omega[1] * f_px
    vy = -omega[2] * x + omega[0] * f_px
    if model == MODEL_PINHOLE:
        vx -= (x * x * omega[1] - x * y * omega[0]) / f_px
        vy -= (x * y * omega[1] - y * y * omega[0]) / f_px
    return vx, vy


@njit(cache=True)
def step_spot(x, y, wx, wy, wz, dt, f_px, model):
    """Spot position after ``dt`` s of constant body rate (wx, wy, wz) rad/s.

    First order: the Euler step of eq. 2.3. Pinhole: the exact rotation of the star
    direction by −ω·dt (Rodrigues) projected back with the focal length.
    """
    if model != MODEL_PINHOLE:
        return x + (wz * y - wy * f_px) * dt, y + (-wz * x + wx * f_px) * dt
    # rotate s = (x, y, f) by angle |ω|dt about −ω (ṡ = −ω × s = s × ω)
    px, py, pz = -wx * dt, -wy * dt, -wz * dt
    th2 = px * px + py * py + pz * pz
    if th2 < 1e-12:
        a = 1.0 - th2 / 6.0
        b = 0.5 - th2 / 24.0
    else:
        th = np.sqrt(th2)
        a = np.sin(th) / th
        b = (1.0 - np.cos(th)) / th2
    sx, sy, sz = x, y, f_px
    cx = py * sz - pz * sy
    cy = pz * sx - px * sz
    cz = px * sy - py * sx
    ccx = py * cz - pz * cy
    ccy = pz * cx - px * cz
    ccz = px * cy - py * cx
    nx = sx + a * cx + b * ccx
    ny = sy + a * cy + b * ccy
    nz = sz + a * cz + b * ccz
    return f_px * nx / nz, f_px * ny / nz


@njit(cache=True)
def predict_trajectory(x0, y0, rates, dt, bias, f_px, model, substeps):
    """Spot positions along gyro samples: (m·substeps + 1, 2) px, starting at (x0, y0).

    ``rates`` (m, 3) measured body rates (rad/s), each held for ``dt`` s; ``bias`` (3,)
    is subtracted (ω = ω_mea − b). ``substeps`` ≥ 1 subdivides each gyro interval so the
    trajectory is sampled densely enough to place extraction squares on every pixel.
    """
    m = rates.shape[0]
    out = np.empty((m * substeps + 1, 2))
    out[0, 0] = x0
    out[0, 1] = y0
    x, y = x0, y0
    h = dt / substeps
    k = 1
    for i in range(m):
        wx = rates[i, 0] - bias[0]
        wy = rates[i, 1] - bias[1]
        wz = rates[i, 2] - bias[2]
        for _ in range(substeps):
            x, y = step_spot(x, y, wx, wy, wz, h, f_px, model)
            out[k, 0] = x
            out[k, 1] = y
            k += 1
    return out


@njit(cache=True)
def substeps_for(rates, dt, f_px, max_step_px):
    """Smallest substep count keeping every trajectory step ≤ ``max_step_px`` pixels."""
    wmax = 0.0
    for i in range(rates.shape[0]):
        w = np.sqrt(rates[i, 0] ** 2 + rates[i, 1] ** 2 + rates[i, 2] ** 2)
        if w > wmax:
            wmax = w
    # |V| ≤ |ω| (f + r) with r ≤ f for any realistic field of view
    step = wmax * 2.0 * f_px * dt
    n = int(np.ceil(step / max_step_px))
    return max(1, n)
