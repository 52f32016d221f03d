"""Spot detection in a full frame for lost-in-space acquisition (numba).

``detect_spots(img, n_sigma, max_spots, box)``: background and noise from a sparse pixel
grid (median, 1.4826·MAD), candidate pixels above ``bg + n_sigma·σ`` that are 3×3 local
maxima, a centre of gravity of background-subtracted pixels above ``bg + 2σ`` in a
``box``×``box`` square around each, and non-maximum suppression (a fainter spot within
``box`` px of a brighter one is dropped). Returns (n, 3) [u (column), v (row), flux]
brightest first — the input Pyramid takes.
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
