"""Spot detection in a full frame for lost-in-space acquisition (numba).

``detect_spots(img, n_sigma, max_spots, box)``: background and noise from a sparse pixel
grid (median, 1.4826·MAD), candidate pixels above ``bg + n_sigma·σ`` that are 3×3 local
maxima, a centre of gravity of background-subtracted pixels above ``bg + 2σ`` in a
``box``×``box`` square around each, and non-maximum suppression (a fainter spot within
``box`` px of a brighter one is dropped). Returns (n, 3) [u (column), v (row), flux]
brightest first — the input Pyramid takes.

``spots_from_windows(spans, values, background, sigma, max_spots)``: the same centre of
gravity and flux on the windows a head's FIND_SPOTS read around its spots (the head did the
background, the 3×3 maxima and the suppression over the whole frame), brightest first.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def frame_background(img, step):
    h, w = img.shape
    vals = np.empty(((h + step - 1) // step) * ((w + step - 1) // step))
    k = 0
    for r in range(0, h, step):
        for c in range(0, w, step):
            vals[k] = img[r, c]
            k += 1
    vals = np.sort(vals[:k])
    med = vals[k // 2]
    dev = np.sort(np.abs(vals - med))
    sig = 1.4826 * dev[k // 2]
    return med, max(sig, 0.5)


@njit(cache=True)
def detect_spots(img, n_sigma, max_spots, box):
    h, w = img.shape
    bg, sig = frame_background(img, 7)
    thr = bg + n_sigma * sig
    low = bg + 2.0 * sig
    half = box // 2
    cap = 4096
    cand = np.empty((cap, 3))
    n = 0
    for r in range(1, h - 1):
        for c in range(1, w - 1):
            v = img[r, c]
            if v <= thr:
                continue
            is_max = True
            for dr in range(-1, 2):
                for dc in range(-1, 2):
                    if dr == 0 and dc == 0:
                        continue
                    nv = img[r + dr, c + dc]
                    if nv > v or (nv == v and (dr < 0 or (dr == 0 and dc < 0))):
                        is_max = False
            if not is_max:
                continue
            su = 0.0
            sv = 0.0
            sw = 0.0
            for rr in range(max(0, r - half), min(h, r + half + 1)):
                for cc in range(max(0, c - half), min(w, c + half + 1)):
                    x = img[rr, cc]
                    if x > low:
                        wt = x - bg
                        su += wt * cc
                        sv += wt * rr
                        sw += wt
            if sw > 0 and n < cap:
                cand[n, 0] = su / sw
                cand[n, 1] = sv / sw
                cand[n, 2] = sw
                n += 1
    order = np.argsort(-cand[:n, 2])
    out = np.empty((min(n, max_spots), 3))
    m = 0
    for j in range(n):
        i = order[j]
        keep = True
        for k in range(m):
            if abs(out[k, 0] - cand[i, 0]) < box and abs(out[k, 1] - cand[i, 1]) < box:
                keep = False
                break
        if keep:
            out[m] = cand[i]
            m += 1
            if m == out.shape[0]:
                break
    return out[:m]


@njit(cache=True)
def window_moments(spans, values, n_windows, low, bg):
    """Per window id 1..``n_windows`` (row ``id − 1``): Σ w·u, Σ w·v, Σ w over the pixels above
    ``low``, w = value − ``bg`` (spans (m, 4) int64 [id, row, c0, c1), values in span order)."""
    out = np.zeros((n_windows, 3))
    k = 0
    for i in range(spans.shape[0]):
        w = spans[i, 0] - 1
        r = spans[i, 1]
        for c in range(spans[i, 2], spans[i, 3]):
            x = values[k]
            k += 1
            if x > low:
                wt = x - bg
                out[w, 0] += wt * c
                out[w, 1] += wt * r
                out[w, 2] += wt
    return out


def spots_from_windows(spans: np.ndarray, values: np.ndarray, background: float, sigma: float,
                       max_spots: int) -> np.ndarray:
    """(n, 3) [u (column), v (row), flux] px/DN of the FIND_SPOTS windows ``spans`` ((m, 4)
    [id 1.., row, c0, c1)) with pixels ``values`` (span order): centre of gravity of the
    background-subtracted pixels above background + 2σ (as :func:`detect_spots`), brightest
    first, at most ``max_spots``; windows with no such pixel are left out."""
    if len(spans) == 0:
        return np.zeros((0, 3))
    n = int(spans[:, 0].max())
    m = window_moments(np.ascontiguousarray(spans, np.int64), np.ascontiguousarray(values, np.float64), n,
                        background + 2.0 * sigma, background)
    m = m[m[:, 2] > 0]
    spots = np.column_stack([m[:, 0] / m[:, 2], m[:, 1] / m[:, 2], m[:, 2]])
    return spots[np.argsort(-spots[:, 2], kind="stable")][:max_spots]
