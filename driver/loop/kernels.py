"""numba kernels of the coupled loop's per-sample path (no Python objects per sample)."""

from __future__ import annotations

import numpy as np
from numba import njit

from ..attitude import quat_to_dcm
from ..camera import project_point


@njit(cache=True)
def project_refs(params, q, refs):
    """Catalog vectors (n, 3) → pixel (u, v) (n, 2) and on-sensor flags under attitude q."""
    a = quat_to_dcm(q)
    n = refs.shape[0]
    uv = np.empty((n, 2))
    ok = np.empty(n, dtype=np.bool_)
    for i in range(n):
        u, v, good = project_point(params, a @ refs[i])
        uv[i, 0] = u
        uv[i, 1] = v
        ok[i] = good
    return uv, ok
