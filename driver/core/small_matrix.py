"""numba helpers for the 3×3 matrices of the filters and fits (no LAPACK call for a 3×3)."""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def inv3_sym(a):
    """Inverse of a symmetric positive-definite 3×3 matrix by cofactors (its upper triangle
    read); all NaN when it is singular or not positive."""
    c00 = a[1, 1] * a[2, 2] - a[1, 2] * a[1, 2]
    c01 = a[0, 2] * a[1, 2] - a[0, 1] * a[2, 2]
    c02 = a[0, 1] * a[1, 2] - a[0, 2] * a[1, 1]
    det = a[0, 0] * c00 + a[0, 1] * c01 + a[0, 2] * c02
    out = np.empty((3, 3))
    if not det > 0.0:
        out[:, :] = np.nan
        return out
    inv = 1.0 / det
    out[0, 0] = c00 * inv
    out[0, 1] = out[1, 0] = c01 * inv
    out[0, 2] = out[2, 0] = c02 * inv
    out[1, 1] = (a[0, 0] * a[2, 2] - a[0, 2] * a[0, 2]) * inv
    out[1, 2] = out[2, 1] = (a[0, 1] * a[0, 2] - a[0, 0] * a[1, 2]) * inv
    out[2, 2] = (a[0, 0] * a[1, 1] - a[0, 1] * a[0, 1]) * inv
    return out
