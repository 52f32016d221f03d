"""Extraction windows as row spans (the representation the firmware and simulator take).

A window set is an int32 array ``(n, 4)`` of rows ``[window_id, row, col_start, col_stop)``
(half-open), sorted by window_id then row, every span inside the sensor
``0 ≤ row < n_rows``, ``0 ≤ col_start < col_stop ≤ n_cols``. Pixel centres are integer
(column u, row v); the square of side k centred on (u, v) covers columns
``round(u − (k−1)/2) … + k − 1`` (likewise rows).

* ``trajectory_window`` — paper 000's window: the union of k×k squares placed on every
  pixel along the predicted trajectory of the spot during the coming exposure.
* ``fixed_window`` — the "traditional" window: one k×k square centred on the last centroid.
* ``concat_windows`` — stack several windows' spans (ids preserved, sorted).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..errors import ConfigError

MAX_WINDOW_SIDE = 512  # px: bound on a window's bounding box (a 20 °/s smear is ~25 px)


@njit(cache=True)
def _square_origin(c, k):
    return int(np.floor(c - (k - 1) / 2.0 + 0.5))


@njit(cache=True)
def _paint(mask, row_lo, row_hi, r_a, r_b, c_a, c_b):
    """Set ``mask[r_a:r_b, c_a:c_b]`` (clipped to the mask) and widen those rows' painted
    column ranges ``[row_lo, row_hi)``."""
    h, w = mask.shape
    r_a = max(r_a, 0)
    r_b = min(r_b, h)
    c_a = max(c_a, 0)
    c_b = min(c_b, w)
    if c_b <= c_a:
        return
    for rr in range(r_a, r_b):
        for cc in range(c_a, c_b):
            mask[rr, cc] = 1
        row_lo[rr] = min(row_lo[rr], c_a)
        row_hi[rr] = max(row_hi[rr], c_b)


@njit(cache=True)
def trajectory_window(traj_uv, k, n_rows, n_cols, window_id):
    """Row spans of the union of k×k squares on the trajectory ``traj_uv`` (m, 2) (col, row).

    The trajectory is resampled so consecutive points are ≤ 0.5 px apart, so no pixel
    along the path is skipped. Squares are clipped to the sensor; an empty result means
    the whole trajectory is off the sensor. The bounding box is capped at
    ``MAX_WINDOW_SIDE`` px (larger requests are clipped around the trajectory's start).
    """
    if k < 1 or k > MAX_WINDOW_SIDE:
        raise ConfigError("window square side k must be 1..512 px")
    if traj_uv.shape[0] < 1 or traj_uv.shape[1] != 2:
        raise ConfigError("trajectory must be (m >= 1, 2) [col, row] px")
    m = traj_uv.shape[0]
    u0 = traj_uv[0, 0]
    v0 = traj_uv[0, 1]
    umin, umax, vmin, vmax = u0, u0, v0, v0
    for i in range(m):
        u, v = traj_uv[i, 0], traj_uv[i, 1]
        umin = min(umin, u)
        umax = max(umax, u)
        vmin = min(vmin, v)
        vmax = max(vmax, v)
    c0 = max(0, _square_origin(umin, k))
    r0 = max(0, _square_origin(vmin, k))
    c1 = min(n_cols, _square_origin(umax, k) + k)
    r1 = min(n_rows, _square_origin(vmax, k) + k)
    c1 = min(c1, c0 + MAX_WINDOW_SIDE)
    r1 = min(r1, r0 + MAX_WINDOW_SIDE)
    if c1 <= c0 or r1 <= r0:
        return np.empty((0, 4), dtype=np.int32)
    h = r1 - r0
    w = c1 - c0
    mask = np.zeros((h, w), dtype=np.uint8)
    row_lo = np.full(h, w, np.int64)        # each row's painted columns lie in [row_lo, row_hi)
    row_hi = np.zeros(h, np.int64)
    painted = False
    pc = 0
    pr = 0
    for i in range(m):
        ua, va = traj_uv[i, 0], traj_uv[i, 1]
        if i + 1 < m:
            ub, vb = traj_uv[i + 1, 0], traj_uv[i + 1, 1]
        else:
            ub, vb = ua, va
        seg = max(abs(ub - ua), abs(vb - va))
        ns = max(1, int(np.ceil(seg / 0.5)))
        for j in range(ns):
            t = j / ns
            cs = _square_origin(ua + t * (ub - ua), k) - c0
            rs = _square_origin(va + t * (vb - va), k) - r0
            if not painted:
                _paint(mask, row_lo, row_hi, rs, rs + k, cs, cs + k)
                painted = True
            elif cs != pc or rs != pr:
                # only what the new square adds to the last one: its rows outside the last
                # square's, whole, and within them its columns outside the last square's
                if rs > pr:
                    _paint(mask, row_lo, row_hi, max(rs, pr + k), rs + k, cs, cs + k)
                elif rs < pr:
                    _paint(mask, row_lo, row_hi, rs, min(rs + k, pr), cs, cs + k)
                if cs > pc:
                    _paint(mask, row_lo, row_hi, max(rs, pr), min(rs, pr) + k, max(cs, pc + k), cs + k)
                elif cs < pc:
                    _paint(mask, row_lo, row_hi, max(rs, pr), min(rs, pr) + k, cs, min(cs + k, pc))
            pc = cs
            pr = rs
    # run-length encode each row within its painted range
    count = 0
    for rr in range(h):
        prev = 0
        for cc in range(row_lo[rr], row_hi[rr]):
            if mask[rr, cc] == 1 and prev == 0:
                count += 1
            prev = mask[rr, cc]
    out = np.empty((count, 4), dtype=np.int32)
    n = 0
    for rr in range(h):
        start = -1
        for cc in range(row_lo[rr], row_hi[rr] + 1):
            on = cc < row_hi[rr] and mask[rr, cc] == 1
            if on and start < 0:
                start = cc
            elif not on and start >= 0:
                out[n, 0] = window_id
                out[n, 1] = r0 + rr
                out[n, 2] = c0 + start
                out[n, 3] = c0 + cc
                n += 1
                start = -1
    return out


@njit(cache=True)
def fixed_window(u, v, k, n_rows, n_cols, window_id):
    """Row spans of one k×k square centred on (u, v) = (col, row), clipped to the sensor."""
    if k < 1 or k > MAX_WINDOW_SIDE:
        raise ConfigError("window square side k must be 1..512 px")
    if not (np.isfinite(u) and np.isfinite(v)):
        raise ConfigError("window centre must be finite")
    c0 = _square_origin(u, k)
    r0 = _square_origin(v, k)
    c_lo, c_hi = max(0, c0), min(n_cols, c0 + k)
    r_lo, r_hi = max(0, r0), min(n_rows, r0 + k)
    if c_hi <= c_lo or r_hi <= r_lo:
        return np.empty((0, 4), dtype=np.int32)
    out = np.empty((r_hi - r_lo, 4), dtype=np.int32)
    for i in range(r_hi - r_lo):
        out[i, 0] = window_id
        out[i, 1] = r_lo + i
        out[i, 2] = c_lo
        out[i, 3] = c_hi
    return out


@njit(cache=True)
def span_pixel_count(spans):
    """Number of pixels covered by ``spans``."""
    n = 0
    for i in range(spans.shape[0]):
        n += spans[i, 3] - spans[i, 2]
    return n


def concat_windows(parts) -> np.ndarray:
    """Stack windows' span arrays into one (n, 4) int32 array sorted by (window_id, row)."""
    if not parts:
        return np.empty((0, 4), dtype=np.int32)
    spans = np.concatenate([np.asarray(p, dtype=np.int32).reshape(-1, 4) for p in parts])
    order = np.lexsort((spans[:, 2], spans[:, 1], spans[:, 0]))
    return np.ascontiguousarray(spans[order])
