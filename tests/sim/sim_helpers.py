"""Helpers shared by the simulator tests (a tiny hand-made catalog)."""

import numpy as np
from gyrostar.catalog import StarCatalog


def one_star_catalog(direction, vmag=5.0, star_id=1):
    v = np.asarray(direction, dtype=np.float64)
    v = v / np.linalg.norm(v)
    return StarCatalog("test", np.array([star_id], dtype=np.int64), v[None, :].copy(), np.array([vmag]), 2025.0)


IDENTITY_Q = np.array([0.0, 0.0, 0.0, 1.0])
