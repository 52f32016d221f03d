"""Smeared star spots: pixel-integrated Gaussian PSF along the true image-plane path (numba).

A star's path over the exposure is sampled at ``n_sub`` sub-step midpoints
(``paths[s, k] = [u, v]`` pixels, [col, row]); its mean photo-signal in pixel (r, c) is

    S(r, c) = Σ_k (N_s / n_sub) · ex_k(c) · ey_k(r),
    ex_k(c) = ½ [erf((c + ½ − u_k)/(√2 σ)) − erf((c − ½ − u_k)/(√2 σ))]   (likewise ey_k)

the exact pixel integral of a Gaussian PSF of σ pixels, summed along the path. For a
straight uniform path the centroid of S equals the exposure-average position exactly;
curvature (roll, rate change) enters as O((L/n_sub)²) with L the path length, so
``substeps_for`` picks ``n_sub`` with ≤ 0.25 px between samples (error ≪ 0.01 px).

Each star only touches its bounding box (path ± 5σ + 1 px). The full-frame and the span
renderers add the same terms in the same order (star, then sub-step), so they give
bit-identical signals; :mod:`gyrostar.mocks.pixel_noise` then makes identical ADUs.

Spans (used across the product: firmware, core, emulators): int32 (n, 4) rows
``[window_id, row, col_start, col_stop)``, half-open column range, sorted by window_id
then row. A span renderer returns the pixels of each span concatenated in span order.
"""

from __future__ import annotations

import math

import numpy as np
from gyrostar.attitude import quat_to_dcm
from gyrostar.camera import P_CX, P_CY, P_F, distort
from numba import njit

BOX_SIGMAS = 5.0
MAX_STEP_PX = 0.25
MAX_SUBSTEPS = 2000


@njit(cache=True, nogil=True)
def star_paths(params, vecs_icrs, quats):
    """Image positions (n_stars, n_sub, 2) [col, row] of ICRS unit vectors at each attitude.

    ``quats`` (n_sub, 4) ICRS→body at the sub-step midpoints. Positions behind the camera
    are NaN. No on-sensor test here (spots near the edge still spill light in).
    """
    n, m = vecs_icrs.shape[0], quats.shape[0]
    out = np.empty((n, m, 2))
    cx, cy, f = params[P_CX], params[P_CY], params[P_F]
    for k in range(m):
        a = quat_to_dcm(quats[k])
        for s in range(n):
            x = a[0, 0] * vecs_icrs[s, 0] + a[0, 1] * vecs_icrs[s, 1] + a[0, 2] * vecs_icrs[s, 2]
            y = a[1, 0] * vecs_icrs[s, 0] + a[1, 1] * vecs_icrs[s, 1] + a[1, 2] * vecs_icrs[s, 2]
            z = a[2, 0] * vecs_icrs[s, 0] + a[2, 1] * vecs_icrs[s, 1] + a[2, 2] * vecs_icrs[s, 2]
            if z <= 0.0:
                out[s, k, 0] = np.nan
                out[s, k, 1] = np.nan
                continue
            xd, yd = distort(params, x / z, y / z)
            out[s, k, 0] = cx + f * xd
            out[s, k, 1] = cy + f * yd
    return out


@njit(cache=True, nogil=True)
def star_paths_boxes(params, vecs_icrs, quats, sigma, width, height):
    """``(star_paths(params, vecs_icrs, quats), star_boxes(…))`` in one call."""
    paths = star_paths(params, vecs_icrs, quats)
    return paths, star_boxes(paths, sigma, width, height)


@njit(cache=True, nogil=True)
def weighted_mean_paths(paths, wts):
    """Σ_k wts[k] · paths[:, k, :] (n, 2): a path's weighted time average."""
    n, m = paths.shape[0], paths.shape[1]
    out = np.zeros((n, 2))
    for s in range(n):
        for k in range(m):
            out[s, 0] += wts[k] * paths[s, k, 0]
            out[s, 1] += wts[k] * paths[s, k, 1]
    return out


@njit(cache=True, nogil=True)
def star_boxes(paths, sigma, width, height):
    """Per star pixel box int64 (n, 4) ``[r0, r1, c0, c1)`` clipped to the sensor (empty if off)."""
    n, m = paths.shape[0], paths.shape[1]
    boxes = np.zeros((n, 4), dtype=np.int64)
    pad = BOX_SIGMAS * sigma + 1.0
    for s in range(n):
        umin, umax, vmin, vmax = np.inf, -np.inf, np.inf, -np.inf
        bad = False
        for k in range(m):
            u, v = paths[s, k, 0], paths[s, k, 1]
            if not (np.isfinite(u) and np.isfinite(v)):
                bad = True
                break
            umin, umax = min(umin, u), max(umax, u)
            vmin, vmax = min(vmin, v), max(vmax, v)
        if bad:
            continue
        c0 = max(0, int(math.floor(umin - pad)))
        c1 = min(width, int(math.ceil(umax + pad)) + 1)
        r0 = max(0, int(math.floor(vmin - pad)))
        r1 = min(height, int(math.ceil(vmax + pad)) + 1)
        if c1 > c0 and r1 > r0:
            boxes[s, 0], boxes[s, 1], boxes[s, 2], boxes[s, 3] = r0, r1, c0, c1
    return boxes


@njit(cache=True, inline="always")
def _edge_erf(edge_index, centre, inv):
    # erf at pixel edge (index − ½) for a Gaussian centred at ``centre``
    return math.erf((np.float64(edge_index) - 0.5 - centre) * inv)


@njit(cache=True, inline="always")
def _step_box(u, v, sigma, r0, r1, c0, c1):
    # the pixels one sub-step's spot reaches: BOX_SIGMAS·σ + 1 px around (u, v) (the padding
    # of :func:`star_boxes`), inside the star's box; (rows [ka, kb), cols [la, lb))
    pad = BOX_SIGMAS * sigma + 1.0
    la = min(max(c0, int(math.floor(u - pad))), c1)     # within [c0, c1] even for a sub-step off the sensor
    lb = max(la, min(c1, int(math.ceil(u + pad)) + 1))
    ka = min(max(r0, int(math.floor(v - pad))), r1)
    kb = max(ka, min(r1, int(math.ceil(v + pad)) + 1))
    return ka, kb, la, lb


@njit(cache=True, nogil=True)
def add_stars_full(signal, paths, electrons, boxes, sigma):
    """Add every star's smeared spot to ``signal`` (H, W) float64, in place: each sub-step's
    spot over the pixels within ``BOX_SIGMAS``·σ + 1 px of it (beyond, a Gaussian PSF holds
    < 1e-6 of the light), so a trail costs its length, not its box's area."""
    n, m = paths.shape[0], paths.shape[1]
    inv = 1.0 / (math.sqrt(2.0) * sigma)
    ex = np.empty(signal.shape[1] + 1)
    ey = np.empty(signal.shape[0] + 1)
    for s in range(n):
        r0, r1, c0, c1 = boxes[s, 0], boxes[s, 1], boxes[s, 2], boxes[s, 3]
        if r1 <= r0:
            continue
        w = electrons[s] / m
        for k in range(m):
            u, v = paths[s, k, 0], paths[s, k, 1]
            ka, kb, la, lb = _step_box(u, v, sigma, r0, r1, c0, c1)
            for c in range(la, lb + 1):
                ex[c - c0] = _edge_erf(c, u, inv)
            for r in range(ka, kb + 1):
                ey[r - r0] = _edge_erf(r, v, inv)
            for r in range(ka, kb):
                a = w * (0.5 * (ey[r - r0 + 1] - ey[r - r0]))
                for c in range(la, lb):
                    signal[r, c] += a * (0.5 * (ex[c - c0 + 1] - ex[c - c0]))


@njit(cache=True, nogil=True)
def _span_groups(spans):
    """Runs of spans with one window id: int64 (g, 6) rows ``[first span, end span, row0,
    row1, col0, col1)`` (the run's bounding rectangle, half-open)."""
    n = spans.shape[0]
    groups = np.empty((n, 6), dtype=np.int64)
    g = 0
    i = 0
    while i < n:
        j = i
        r0, r1, c0, c1 = spans[i, 1], spans[i, 1] + 1, spans[i, 2], spans[i, 3]
        while j < n and spans[j, 0] == spans[i, 0]:
            r0, r1 = min(r0, spans[j, 1]), max(r1, spans[j, 1] + 1)
            c0, c1 = min(c0, spans[j, 2]), max(c1, spans[j, 3])
            j += 1
        groups[g, 0], groups[g, 1], groups[g, 2], groups[g, 3], groups[g, 4], groups[g, 5] = i, j, r0, r1, c0, c1
        g += 1
        i = j
    return groups[:g]


@njit(cache=True, nogil=True)
def add_stars_spans(signal, spans, paths, electrons, boxes, sigma):
    """Add every star's spot to the span pixels ``signal`` (m,) (span order), in place.

    Per star that touches a span, the edge-erf tables of its box are computed once per
    sub-step (the same values and sub-step pixels :func:`add_stars_full` uses), then summed on
    the span pixels. A star is tested against each window's bounding rectangle before its
    spans, so the stars of the field that no window reaches cost a few comparisons each.
    """
    n, m = paths.shape[0], paths.shape[1]
    inv = 1.0 / (math.sqrt(2.0) * sigma)
    starts = np.empty(spans.shape[0] + 1, dtype=np.int64)
    starts[0] = 0
    for i in range(spans.shape[0]):
        starts[i + 1] = starts[i] + (spans[i, 3] - spans[i, 2])
    groups = _span_groups(spans)
    hit = np.zeros(groups.shape[0], np.bool_)
    for s in range(n):
        r0, r1, c0, c1 = boxes[s, 0], boxes[s, 1], boxes[s, 2], boxes[s, 3]
        if r1 <= r0:
            continue
        touched = False
        for g in range(groups.shape[0]):
            hit[g] = False
            if groups[g, 2] >= r1 or groups[g, 3] <= r0 or groups[g, 4] >= c1 or groups[g, 5] <= c0:
                continue
            for i in range(groups[g, 0], groups[g, 1]):
                if r0 <= spans[i, 1] < r1 and spans[i, 2] < c1 and spans[i, 3] > c0:
                    hit[g] = True
                    touched = True
                    break
        if not touched:
            continue
        ex = np.empty((m, c1 - c0 + 1))
        ey = np.empty((m, r1 - r0 + 1))
        sub = np.empty((m, 4), dtype=np.int64)
        for k in range(m):
            u, v = paths[s, k, 0], paths[s, k, 1]
            ka, kb, la, lb = _step_box(u, v, sigma, r0, r1, c0, c1)
            sub[k, 0], sub[k, 1], sub[k, 2], sub[k, 3] = ka, kb, la, lb
            for c in range(la, lb + 1):
                ex[k, c - c0] = _edge_erf(c, u, inv)
            for r in range(ka, kb + 1):
                ey[k, r - r0] = _edge_erf(r, v, inv)
        w = electrons[s] / m
        for g in range(groups.shape[0]):
            if not hit[g]:
                continue
            for i in range(groups[g, 0], groups[g, 1]):
                r = spans[i, 1]
                if r < r0 or r >= r1:
                    continue
                a0, a1 = max(c0, spans[i, 2]), min(c1, spans[i, 3])
                if a1 <= a0:
                    continue
                base = starts[i] - spans[i, 2]
                for k in range(m):
                    if r < sub[k, 0] or r >= sub[k, 1]:
                        continue
                    a = w * (0.5 * (ey[k, r - r0 + 1] - ey[k, r - r0]))
                    for c in range(max(a0, sub[k, 2]), min(a1, sub[k, 3])):
                        signal[base + c] += a * (0.5 * (ex[k, c - c0 + 1] - ex[k, c - c0]))


@njit(cache=True, nogil=True)
def lit_rows(boxes, height):
    """bool (height,): rows inside at least one star box."""
    lit = np.zeros(height, dtype=np.bool_)
    for s in range(boxes.shape[0]):
        for r in range(boxes[s, 0], boxes[s, 1]):
            lit[r] = True
    return lit


@njit(cache=True, nogil=True)
def clear_boxes(signal, boxes):
    """Zero the star boxes of ``signal`` (H, W) again, so the buffer can be reused."""
    for s in range(boxes.shape[0]):
        for r in range(boxes[s, 0], boxes[s, 1]):
            for c in range(boxes[s, 2], boxes[s, 3]):
                signal[r, c] = 0.0


@njit(cache=True)
def _span_fault(spans, width, height):
    """0 when every span lies on the sensor with col_start < col_stop and the spans are sorted
    by window id then row; 1 for a span off the sensor or empty, 2 for an order fault."""
    for i in range(spans.shape[0]):
        row, c0, c1 = spans[i, 1], spans[i, 2], spans[i, 3]
        if row < 0 or row >= height or c0 < 0 or c1 > width or c1 <= c0:
            return 1
    for i in range(1, spans.shape[0]):
        if spans[i, 0] < spans[i - 1, 0] or (spans[i, 0] == spans[i - 1, 0] and spans[i, 1] < spans[i - 1, 1]):
            return 2
    return 0


def check_spans(spans: np.ndarray, width: int, height: int) -> np.ndarray:
    """Validate a span array (see module docstring); returns it as contiguous int32 (n, 4)."""
    from gyrostar.errors import ConfigError

    a = np.asarray(spans)
    if a.ndim != 2 or a.shape[1] != 4 or a.dtype.kind not in "iu":
        raise ConfigError(f"spans must be an integer array of shape (n, 4), got {a.dtype} {a.shape}")
    a = np.ascontiguousarray(a, dtype=np.int32)
    fault = _span_fault(a, width, height)
    if fault == 1:
        raise ConfigError(f"spans must lie on the {width}x{height} sensor with col_start < col_stop")
    if fault == 2:
        raise ConfigError("spans must be sorted by window_id then row")
    return a
