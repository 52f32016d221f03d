"""How many catalog stars fall in a square field of view at random attitudes (numba).

A star is in the field when it is in front of the camera and inside the square
``|X/Z| ≤ tan(θ/2)``, ``|Y/Z| ≤ tan(θ/2)`` (θ the full field, body = camera frame, so the
random roll of each attitude turns the square on the sky). Used by ``gyrostar eval
starcount`` (paper 001, Table 1).
"""

from __future__ import annotations

import math

import numpy as np
from gyrostar.attitude import quat_to_dcm
from gyrostar.errors import ConfigError
from numba import njit

from .trajectory import random_attitudes

BINS = ("0", "1", "2", "3", "4", "5", "6", ">6")


@njit(cache=True, nogil=True)
def count_in_square(vecs, quats, tan_half):
    """Stars of ``vecs`` (n, 3) ICRS in the square field of each attitude of ``quats`` (m, 4)."""
    m = quats.shape[0]
    out = np.zeros(m, dtype=np.int64)
    # a star in the square is within the half-diagonal of the boresight
    cos_diag = 1.0 / math.sqrt(1.0 + 2.0 * tan_half * tan_half)
    for i in range(m):
        a = quat_to_dcm(quats[i])
        cnt = 0
        for s in range(vecs.shape[0]):
            vx, vy, vz = vecs[s, 0], vecs[s, 1], vecs[s, 2]
            z = a[2, 0] * vx + a[2, 1] * vy + a[2, 2] * vz
            if z < cos_diag:
                continue
            x = a[0, 0] * vx + a[0, 1] * vy + a[0, 2] * vz
            y = a[1, 0] * vx + a[1, 1] * vy + a[1, 2] * vz
            if abs(x) <= tan_half * z and abs(y) <= tan_half * z:
                cnt += 1
        out[i] = cnt
    return out


def star_count_distribution(vectors: np.ndarray, fov_deg: float, trials: int, seed: int,
                            chunk: int = 1000, advance=None) -> dict:
    """Percentages of fields holding 0..6 and > 6 stars, the mean and the raw counts."""
    if not (0 < fov_deg < 90):
        raise ConfigError(f"fov_deg must be in (0, 90), got {fov_deg}")
    if trials < 1:
        raise ConfigError(f"trials must be >= 1, got {trials}")
    rng = np.random.default_rng(seed)
    tan_half = math.tan(math.radians(fov_deg) / 2.0)
    vecs = np.ascontiguousarray(vectors, dtype=np.float64)
    counts = np.empty(trials, dtype=np.int64)
    for start in range(0, trials, chunk):
        n = min(chunk, trials - start)
        counts[start:start + n] = count_in_square(vecs, random_attitudes(n, rng), tan_half)
        if advance is not None:
            advance(n)
    hist = np.bincount(np.minimum(counts, 7), minlength=8)
    result = {b: 100.0 * float(hist[i]) / trials for i, b in enumerate(BINS)}
    result["mean"] = float(counts.mean())
    return {"distribution": result, "counts": counts}
