"""Faint neighbours: catalog stars the sensor may see that the star index leaves out.

An index stops at its limiting magnitude and keeps one star of each close double. The
sensor does not stop there: with magnitude noise σ_m a star up to ~3σ_m fainter than the
limit is sometimes detected, and an index star near the limit is sometimes missed. A spot
of such a faint star, next to an index star that was missed, gets that index star's label
— the attitude is right, one label is wrong. :class:`FaintStars` holds the left-out stars
(every catalog star not in the index down to ``index.mag_limit + depth_mag``) so an
identifier can drop a label whose spot is within its tolerance of one of them.
Directions are ICRS unit vectors.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from numba import njit

from ..attitude import quat_to_dcm
from ..errors import ConfigError
from .index import any_within, voxel_grid

DEPTH_MAG = 0.6     # mag below the index limit: 3σ of the 0.2 mag sensor noise of paper 001
VOX_H = 0.02        # voxel edge of the faint stars' grid (unit-vector units, ~1.1°)


@dataclasses.dataclass
class FaintStars:
    """Unit vectors (m, 3) of the catalog stars an index leaves out, in a voxel grid
    (``gyrostar.starid.index.voxel_grid``: ``vox_vec`` the vectors in cell order, ``vox_start``
    each cell's first, ``vox_g`` cells per axis of edge ``vox_h``)."""

    vectors: np.ndarray
    depth_mag: float

    def __post_init__(self) -> None:
        self.vectors = np.ascontiguousarray(self.vectors, dtype=np.float64).reshape(-1, 3)
        self.vox_h = VOX_H
        self.vox_g, self.vox_start, order = voxel_grid(self.vectors, VOX_H)
        self.vox_vec = np.ascontiguousarray(self.vectors[order])


@njit(cache=True)
def drop_near_faint(q, b, match, vox_vec, vox_start, h, g, radius):
    """Unlabel (``match[i] = -1``, in place) every labelled spot ``b`` (n, 3, body) that
    attitude ``q`` (ICRS → body) puts within ``radius`` (rad) of a faint star of the grid
    (:class:`FaintStars`); returns how many."""
    a = quat_to_dcm(q)
    dropped = 0
    c = np.empty(3)
    for i in range(b.shape[0]):
        if match[i] < 0:
            continue
        for k in range(3):           # body → ICRS: Aᵀ b
            c[k] = a[0, k] * b[i, 0] + a[1, k] * b[i, 1] + a[2, k] * b[i, 2]
        if any_within(vox_vec, vox_start, h, g, c, radius):
            match[i] = -1
            dropped += 1
    return dropped


def faint_stars(catalog, index, depth_mag: float = DEPTH_MAG) -> FaintStars:
    """The stars of ``catalog`` (a :class:`gyrostar.catalog.StarCatalog`, ideally
    ``depth_mag`` deeper than ``index``) that ``index`` (a :class:`StarIndex` of the same
    catalog) leaves out, down to ``index.mag_limit + depth_mag`` or as deep as the catalog
    goes (a catalog that ends at the index's limit leaves only the pruned doubles)."""
    if not depth_mag >= 0.0:
        raise ConfigError(f"faint-star depth must be ≥ 0 mag, got {depth_mag!r}")
    keep = (catalog.vmag <= index.mag_limit + depth_mag) & ~np.isin(catalog.ids, index.ids)
    return FaintStars(catalog.vectors[keep], float(depth_mag))
