"""What an identifier returns, and the centroid → body-vector conversion they share."""

from __future__ import annotations

import dataclasses

import numpy as np

from ..camera import unproject_many
from ..errors import ConfigError


def to_body_vectors(params: np.ndarray, uv) -> np.ndarray:
    """Centroids (n, 2) [col, row] px → unit body vectors (n, 3), with input checks."""
    pts = np.ascontiguousarray(np.asarray(uv, dtype=np.float64).reshape(-1, 2) if np.size(uv) else
                               np.empty((0, 2)))
    if not np.all(np.isfinite(pts)):
        raise ConfigError("centroids must be finite pixel coordinates")
    return unproject_many(params, pts)


@dataclasses.dataclass(frozen=True)
class StarIdResult:
    """One image's identification.

    ``index`` (n,): navigation-star index of each centroid in the :class:`StarIndex`, -1
    when unidentified; ``ids`` (n,): catalog ids (HIP / Gaia), -1 likewise; ``q``: attitude
    ICRS → body ([x, y, z, w]) from QUEST over the identified stars; ``ok``: accepted (at
    least two stars, every residual within tolerance); ``p_false``: analytic expected number
    of false matches (Pyramid; NaN for tracking methods); ``status``: why it failed;
    ``triangles``: star triangles the search tried (Pyramid; 0 for the other methods).
    """

    index: np.ndarray
    ids: np.ndarray
    q: np.ndarray
    ok: bool
    status: str
    p_false: float
    method: str
    triangles: int = 0

    @property
    def n_identified(self) -> int:
        return int(np.count_nonzero(self.index >= 0))

    @staticmethod
    def make(star_index, match, q, ok, status, p_false, method, triangles: int = 0) -> StarIdResult:
        match = np.asarray(match, dtype=np.int64)
        if not ok:
            match = np.full(match.shape, -1, dtype=np.int64)
        ids = np.full(match.shape, -1, dtype=np.int64)
        got = match >= 0
        ids[got] = star_index.ids[match[got]]
        return StarIdResult(match, ids, np.asarray(q, dtype=np.float64), bool(ok), status, float(p_false), method,
                            int(triangles))
