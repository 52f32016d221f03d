"""The head's FIND_SPOTS scan in Python, rule for rule as ``firmware/core/gs_spots.c``.

The head emulator answers FIND_SPOTS with it; ``tests/firmware`` checks it against the C
firmware (host program) pixel for pixel. The rules are the FIND_SPOTS doc of
``firmware/proto/protocol.toml``: background and noise from a 10-bit histogram of every
``spot_grid``-th pixel of every ``spot_grid``-th row (median; σ = max(1.4826·MAD, 0.5) DN, in
1/16 DN with the firmware's integer rounding), 3×3 local maxima above the threshold taken in
row-major order, scored by their 8 neighbours' excess over the background (a hot pixel
ranks last), into a bounded best-first list with non-maximum suppression.
"""

from __future__ import annotations

import numpy as np
from gyrostar.head.client import spot_spans
from gyrostar.protocol.defs import LIMITS
from numba import njit

GRID = LIMITS["spot_grid"]


def check_settings(n_sigma_x16: int, max_spots: int, box: int) -> int:
    """0 if usable, else the SPOT_SETTINGS detail (1 n_sigma, 2 max_spots, 3 box, 4 spans, 5 pixels)."""
    if n_sigma_x16 == 0:
        return 1
    if not 1 <= max_spots <= LIMITS["max_windows"]:
        return 2
    if box < 3 or box > LIMITS["spot_box_max"] or box % 2 == 0:
        return 3
    if max_spots * box > LIMITS["max_spans"]:
        return 4
    if max_spots * box * box > LIMITS["pixel_budget"]:
        return 5
    return 0


@njit(cache=True)
def _rank(hist, k):
    cum = 0
    for v in range(hist.size):
        cum += hist[v]
        if cum > k:
            return v
    return hist.size - 1


@njit(cache=True)
def _background(img, grid):
    hist = np.zeros(1024, np.int64)
    k = 0
    for r in range(0, img.shape[0], grid):
        for c in range(0, img.shape[1], grid):
            hist[img[r, c]] += 1
            k += 1
    med = _rank(hist, k // 2)
    dev = np.zeros(1024, np.int64)
    for v in range(1024):
        dev[abs(v - med)] += hist[v]
    mad = _rank(dev, k // 2)
    sig = (mad * 237216 + 5000) // 10000
    return 16 * med, max(sig, 8)


@njit(cache=True)
def _scan(img, bg_x16, thr_x16, max_spots, box, spots):
    """Local maxima into spots[:, (row, col, score x16)]; returns (n kept, candidates)."""
    h, w = img.shape
    n = 0
    cand = 0
    for r in range(1, h - 1):
        for c in range(1, w - 1):
            v = img[r, c]
            if 16 * v <= thr_x16:
                continue
            if img[r - 1, c - 1] >= v or img[r - 1, c] >= v or img[r - 1, c + 1] >= v or img[r, c - 1] >= v:
                continue
            if img[r, c + 1] > v or img[r + 1, c - 1] > v or img[r + 1, c] > v or img[r + 1, c + 1] > v:
                continue
            cand += 1
            v = 0
            for dr in range(-1, 2):
                for dc in range(-1, 2):
                    if dr != 0 or dc != 0:
                        v += 16 * img[r + dr, c + dc] - bg_x16
            v = max(v, 0)
            covered = False
            for i in range(n):
                if spots[i, 2] >= v and abs(spots[i, 0] - r) < box and abs(spots[i, 1] - c) < box:
                    covered = True
                    break
            if covered:
                continue
            m = 0
            for i in range(n):
                if not (abs(spots[i, 0] - r) < box and abs(spots[i, 1] - c) < box):
                    spots[m] = spots[i]
                    m += 1
            n = m
            at = n
            while at > 0 and spots[at - 1, 2] < v:
                at -= 1
            if at >= max_spots:
                continue
            last = n if n < max_spots else max_spots - 1
            for i in range(last, at, -1):
                spots[i] = spots[i - 1]
            spots[at, 0] = r
            spots[at, 1] = c
            spots[at, 2] = v
            if n < max_spots:
                n += 1
    return n, cand


def find_spots(img: np.ndarray, n_sigma_x16: int, max_spots: int, box: int) -> dict:
    """FIND_SPOTS over a 10-bit frame ``img`` (rows × cols; values above 1023 clip).
    Returns background_x16, sigma_x16, threshold_x16, candidates, spots ((n, 3) int32
    [row, col, flux DN], best score first) and spans ((m, 4) int32 window set, ids 1..n)."""
    img = np.minimum(np.asarray(img), 0x3FF).astype(np.int64)
    h, w = img.shape
    bg, sig = _background(img, GRID)
    thr = bg + (n_sigma_x16 * sig + 8) // 16
    spots = np.zeros((max(max_spots, 1) + 1, 3), np.int64)
    n, cand = (0, 0) if h < 3 or w < 3 else _scan(img, bg, thr, max_spots, box, spots)
    spots = spots[:n].copy()
    spots[:, 2] = np.minimum(spots[:, 2] // 16, 0xFFFF)      # the tail's flux, DN
    spots = spots.astype(np.int32)
    spans = spot_spans(spots, box, w, h)
    return {"background_x16": int(bg), "sigma_x16": int(sig), "threshold_x16": int(thr), "candidates": int(cand),
            "spots": spots, "spans": spans}
