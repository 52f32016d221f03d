"""Mortari's k-vector: O(1) range search in a sorted array (Mortari & Neta 2000).

For ``y`` sorted ascending (n values) a straight line ``z(i) = m·i + q`` runs from just
below ``y[0]`` to just above ``y[n-1]``; ``k[i]`` is the number of values ``≤ z(i)``.
A query ``[lo, hi]`` maps both ends through the line to ``k`` indices, which bracket the
answer to within the few elements between two line steps; those are trimmed by direct
comparison. ``build`` runs once (numpy); ``query`` is numba and allocation free.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..errors import ConfigError


def build(y: np.ndarray) -> tuple[np.ndarray, float, float]:
    """k-vector of an ascending float array: ``(k int64 (n,), m, q)``."""
    y = np.asarray(y, dtype=np.float64)
    n = y.shape[0]
    if n < 2:
        raise ConfigError(f"a k-vector needs at least 2 values, got {n}")
    if np.any(np.diff(y) < 0.0):
        raise ConfigError("k-vector input must be sorted ascending")
    span = y[-1] - y[0]
    delta = max(span, abs(y[0]), 1.0) * 1e-12 * n
    m = (span + 2.0 * delta) / (n - 1)
    q = y[0] - delta
    z = m * np.arange(n) + q
    k = np.searchsorted(y, z, side="right").astype(np.int64)
    return k, float(m), float(q)


@njit(cache=True)
def query(y, k, m, q, lo, hi):
    """Half-open index range ``[start, end)`` of the values of ``y`` in ``[lo, hi]``."""
    n = y.shape[0]
    if hi < lo or n == 0:
        return 0, 0
    jb = int(np.floor((lo - q) / m))
    jt = int(np.ceil((hi - q) / m))
    if jt < 0 or jb > n - 1:
        return 0, 0
    if jb < 0:
        start = 0
    else:
        start = k[jb]
    if jt > n - 1:
        end = n
    else:
        end = k[jt]
    while start > 0 and y[start - 1] >= lo:
        start -= 1
    while start < n and y[start] < lo:
        start += 1
    while end > start and y[end - 1] > hi:
        end -= 1
    while end < n and y[end] <= hi:
        end += 1
    if end < start:
        end = start
    return start, end
