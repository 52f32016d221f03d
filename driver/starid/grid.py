"""Grid patterns (Padgett & Kreutz-Delgado 1997) and the lost-in-space grid baseline.

Pattern of a reference star r among stars ``vecs`` (unit vectors, any common frame):
1. take the stars within the pattern radius ``pr`` of r onto the tangent plane at r
   (gnomonic, rad) — r moves to the centre;
2. the neighbour is the nearest of them outside the buffer radius ``br``;
3. rotate the plane so that the neighbour lies on +x;
4. lay a g×g grid of cells of side ``cell`` (rad) centred on r; the pattern is the sorted
   list of occupied cell numbers ``iy·g + ix`` (paper 001's storage: no g² bit vector).
Two stars match when their patterns share at least ξ cells.

:class:`GridDatabase` holds the pattern of every catalog star (built over the catalog
itself) and, for lost-in-space, an inverted table cell → stars, cached as a file.
:func:`identify_grid` is the baseline: each observed star's pattern votes through the
inverted table; the best star with ≥ ξ votes (and strictly more than the runner-up) is
its match; the image is accepted when ≥ 2 matches survive QUEST residual verification.
"""

from __future__ import annotations

import dataclasses
import math
import os
import tempfile

import numpy as np
from numba import njit

from ..errors import ConfigError
from ..paths import cache_dir
from .result import StarIdResult, to_body_vectors
from .verify import verify_matches

GRID_DB_VERSION = 1


@dataclasses.dataclass(frozen=True)
class GridParams:
    """Grid parameters: ``g`` cells per side, ``cell_deg`` cell side, ``br_deg`` buffer
    radius, ``pr_deg`` pattern radius (default g·cell/2), ``xi`` minimum shared cells.
    Paper 001: g = 40, cell 0.2°, br = 0.3°."""

    g: int = 40
    cell_deg: float = 0.2
    br_deg: float = 0.3
    pr_deg: float = 0.0
    xi: int = 4

    def __post_init__(self) -> None:
        if self.g < 2 or self.cell_deg <= 0 or self.br_deg < 0 or self.xi < 1 or self.pr_deg < 0:
            raise ConfigError(f"bad grid parameters {self}")

    @property
    def pr(self) -> float:
        return math.radians(self.pr_deg if self.pr_deg > 0 else self.g * self.cell_deg / 2.0)

    @property
    def br(self) -> float:
        return math.radians(self.br_deg)

    @property
    def cell(self) -> float:
        return math.radians(self.cell_deg)


@njit(cache=True)
def tangent_coords(vecs, ref, br, pr):
    """Gnomonic coordinates (rad) at star ``ref`` of the other stars within ``pr``.

    Returns ``(xs, ys, idx, dots, k)``: the first ``k`` entries are valid; ``dots`` is cos of
    the distance for stars outside ``br`` and -2 for those inside (not neighbour material)."""
    m = vecs.shape[0]
    xs = np.empty(m)
    ys = np.empty(m)
    idx = np.empty(m, dtype=np.int64)
    dots = np.empty(m)
    k = tangent_coords_into(vecs, ref, br, pr, xs, ys, idx, dots)
    return xs, ys, idx, dots, k


@njit(cache=True)
def tangent_coords_into(vecs, ref, br, pr, xs, ys, idx, dots):
    """:func:`tangent_coords` into caller buffers (≥ len(vecs) each); returns ``k``."""
    r = vecs[ref]
    if abs(r[0]) < 0.9:
        e1 = np.array([0.0, -r[2], r[1]])
    else:
        e1 = np.array([-r[2], 0.0, r[0]])
    e1 /= np.sqrt(e1 @ e1)
    e2 = np.array([r[1] * e1[2] - r[2] * e1[1], r[2] * e1[0] - r[0] * e1[2], r[0] * e1[1] - r[1] * e1[0]])
    cos_pr = np.cos(pr)
    cos_br = np.cos(br)
    m = vecs.shape[0]
    k = 0
    for s in range(m):
        if s == ref:
            continue
        v = vecs[s]
        d = v[0] * r[0] + v[1] * r[1] + v[2] * r[2]
        if d < cos_pr:
            continue
        xs[k] = (v[0] * e1[0] + v[1] * e1[1] + v[2] * e1[2]) / d
        ys[k] = (v[0] * e2[0] + v[1] * e2[1] + v[2] * e2[2]) / d
        idx[k] = s
        dots[k] = d if d < cos_br else -2.0
        k += 1
    return k


@njit(cache=True)
def nth_neighbour(dots, k, rank):
    """Position (in the coordinate arrays) of the (rank+1)-th nearest star outside br, or -1."""
    taken = np.zeros(rank, dtype=np.int64)
    nb = -1
    for r in range(rank + 1):
        best = -1.5
        nb = -1
        for t in range(k):
            skip = False
            for u in range(r):
                if taken[u] == t:
                    skip = True
            if not skip and dots[t] > best:
                best = dots[t]
                nb = t
        if nb < 0:
            return -1
        if r < rank:
            taken[r] = nb
    return nb


@njit(cache=True)
def cells_from(xs, ys, k, nb, g, cell, out):
    """Sorted unique occupied cells with the grid turned so that entry ``nb`` is on +x."""
    ang = np.arctan2(ys[nb], xs[nb])
    c = np.cos(ang)
    sn = np.sin(ang)
    half = 0.5 * g * cell
    n = 0
    for t in range(k):
        x = c * xs[t] + sn * ys[t]
        y = -sn * xs[t] + c * ys[t]
        ix = int(np.floor((x + half) / cell))
        iy = int(np.floor((y + half) / cell))
        if ix < 0 or iy < 0 or ix >= g or iy >= g:
            continue
        out[n] = iy * g + ix
        n += 1
    # insertion sort + unique (patterns hold a few tens of cells)
    for t in range(1, n):
        v = out[t]
        u = t - 1
        while u >= 0 and out[u] > v:
            out[u + 1] = out[u]
            u -= 1
        out[u + 1] = v
    m = 0
    for t in range(n):
        if t == 0 or out[t] != out[m - 1]:
            out[m] = out[t]
            m += 1
    return m


@njit(cache=True)
def grid_pattern(vecs, ref, br, pr, g, cell, out, rank=0):
    """Pattern of star ``ref`` among ``vecs`` into ``out`` (≥ len(vecs)); returns ``(n_cells, nb)``.

    ``nb`` is the index (into ``vecs``) of the neighbour star, -1 if none (then no pattern).
    ``rank`` > 0 orients the grid on the (rank+1)-th nearest star outside ``br`` instead
    (alternative orientations of a catalog pattern, see :mod:`gyrostar.starid.extended`).
    """
    xs, ys, idx, dots, k = tangent_coords(vecs, ref, br, pr)
    nb = nth_neighbour(dots, k, rank)
    if nb < 0:
        return 0, -1
    return cells_from(xs, ys, k, nb, g, cell, out), idx[nb]


@njit(cache=True)
def shared_cells(a, na, b, nb):
    """Number of cell numbers common to two sorted patterns."""
    i = 0
    j = 0
    c = 0
    while i < na and j < nb:
        if a[i] == b[j]:
            c += 1
            i += 1
            j += 1
        elif a[i] < b[j]:
            i += 1
        else:
            j += 1
    return c


@njit(cache=True)
def _build_db(vec, nbs, nbi, br, pr, g, cell):
    n = vec.shape[0]
    counts = np.zeros(n + 1, dtype=np.int64)
    nbr = -np.ones(n, dtype=np.int64)
    cap = 16 * n + 16
    cells = np.empty(cap, dtype=np.int32)
    buf = np.empty(1024, dtype=np.int64)
    for s in range(n):
        m = nbs[s + 1] - nbs[s]
        loc = np.empty((m + 1, 3))
        loc[0] = vec[s]
        for t in range(m):
            loc[t + 1] = vec[nbi[nbs[s] + t]]
        if buf.shape[0] < m + 1:
            buf = np.empty(2 * (m + 1), dtype=np.int64)
        k, nb = grid_pattern(loc, 0, br, pr, g, cell, buf)
        if nb >= 0:
            nbr[s] = nbi[nbs[s] + nb - 1]
        while counts[s] + k > cap:
            cap *= 2
            bigger = np.empty(cap, dtype=np.int32)
            bigger[:counts[s]] = cells[:counts[s]]
            cells = bigger
        for t in range(k):
            cells[counts[s] + t] = buf[t]
        counts[s + 1] = counts[s] + k
    return counts, cells[:counts[n]].copy(), nbr


@dataclasses.dataclass(frozen=True, eq=False)
class GridDatabase:
    """Pattern of every indexed star (CSR ``start``/``cells``), its neighbour star and the
    inverted table ``cell → stars`` (CSR ``inv_start``/``inv_stars``)."""

    params: GridParams
    start: np.ndarray
    cells: np.ndarray
    neighbour: np.ndarray
    inv_start: np.ndarray
    inv_stars: np.ndarray


def build_grid_database(index, params: GridParams) -> GridDatabase:
    """Patterns of all stars of a :class:`StarIndex` over the catalog (neighbour table).

    Needs an index whose pairs reach ``pr`` and that is not thinned (``per_field`` 0)."""
    if index.per_field != 0:
        raise ConfigError("the grid database needs an unthinned index (per_field 0)")
    if index.max_sep < params.pr:
        raise ConfigError(f"index pairs reach {math.degrees(index.max_sep):.2f}° < pattern radius")
    start, cells, nbr = _build_db(index.vectors, index.nb_start, index.nb_idx, params.br, params.pr,
                                  params.g, params.cell)
    star_of = np.repeat(np.arange(len(index), dtype=np.int32), np.diff(start))
    order = np.argsort(cells, kind="stable")
    inv_start = np.zeros(params.g * params.g + 1, dtype=np.int64)
    np.cumsum(np.bincount(cells, minlength=params.g * params.g), out=inv_start[1:])
    return GridDatabase(params, start, cells, nbr, inv_start, star_of[order])


def load_grid_database(index, params: GridParams) -> GridDatabase:
    """:func:`build_grid_database`, cached under ``cache_dir("starid")`` by index and params."""
    from .index import INDEX_VERSION

    p = params
    key = (f"{index.catalog}_m{index.mag_limit:.3f}_e{index.epoch:.3f}_f{math.degrees(index.max_sep):.4f}"
           f"_n{index.per_field}_s{len(index)}_i{INDEX_VERSION}")
    path = cache_dir("starid") / (f"grid_{key}_g{p.g}_c{p.cell_deg:.4f}_b{p.br_deg:.4f}"
                                  f"_p{math.degrees(p.pr):.4f}_v{GRID_DB_VERSION}.npz")
    if path.exists():
        try:
            with np.load(path) as z:
                return GridDatabase(params, z["start"], z["cells"], z["neighbour"], z["inv_start"], z["inv_stars"])
        except (OSError, KeyError, ValueError):
            path.unlink(missing_ok=True)
    db = build_grid_database(index, params)
    fd, tmp = tempfile.mkstemp(dir=path.parent, suffix=".npz")
    os.close(fd)
    np.savez(tmp, start=db.start, cells=db.cells, neighbour=db.neighbour, inv_start=db.inv_start,
             inv_stars=db.inv_stars)
    os.replace(tmp, path)
    return db


@njit(cache=True)
def grid_lis_core(b, n_ref, br, pr, g, cell, xi, inv_start, inv_stars, n_cat, votes):
    """Each of the first ``n_ref`` observed stars votes; returns ``(match, nb_obs)``.

    ``votes`` int32 (n_cat,) zeros (work, left zeroed). ``nb_obs``: observed neighbour of
    each reference (-1 none)."""
    n = b.shape[0]
    match = -np.ones(n, dtype=np.int64)
    nb_obs = -np.ones(n, dtype=np.int64)
    buf = np.empty(n + 1, dtype=np.int64)
    touched = np.empty(4096, dtype=np.int64)
    for r in range(min(n, n_ref)):
        k, nb = grid_pattern(b, r, br, pr, g, cell, buf)
        nb_obs[r] = nb
        if nb < 0 or k < xi:
            continue
        nt = 0
        for t in range(k):
            c = buf[t]
            for p in range(inv_start[c], inv_start[c + 1]):
                s = inv_stars[p]
                if votes[s] == 0:
                    if nt == touched.shape[0]:
                        bigger = np.empty(2 * nt, dtype=np.int64)
                        bigger[:nt] = touched
                        touched = bigger
                    touched[nt] = s
                    nt += 1
                votes[s] += 1
        best = -1
        bv = 0
        second = 0
        for t in range(nt):
            s = touched[t]
            v = votes[s]
            if v > bv:
                second = bv
                bv = v
                best = s
            elif v > second:
                second = v
            votes[s] = 0
        if bv >= xi and bv > second:
            match[r] = best
    return match, nb_obs


@dataclasses.dataclass
class GridIdentifier:
    """Lost-in-space grid baseline over a :class:`StarIndex` and its :class:`GridDatabase`."""

    index: object
    db: GridDatabase
    camera: object
    sigma_px: float = 1.0
    n_sigma: float = 4.0
    max_ref: int = 10

    def __post_init__(self) -> None:
        self._params = self.camera.as_array()
        self.tol = self.n_sigma * 1.25 * self.sigma_px / self.camera.focal_length_px + 2e-6
        self._votes = np.zeros(len(self.index), dtype=np.int32)

    def identify_vectors(self, b: np.ndarray):
        """``(StarIdResult, nb_obs)`` for body unit vectors (n, 3), brightest first."""
        p = self.db.params
        b = np.ascontiguousarray(b)
        match, nb_obs = grid_lis_core(b, self.max_ref, p.br, p.pr, p.g, p.cell, p.xi, self.db.inv_start,
                                      self.db.inv_stars, len(self.index), self._votes)
        q, out, nok, _ = verify_matches(b, self.index.vectors, match, self.tol)
        ok = nok >= 2
        return StarIdResult.make(self.index, out, q, ok, "ok" if ok else "fewer than 2 verified matches",
                                 math.nan, "grid"), nb_obs

    def identify(self, uv: np.ndarray) -> StarIdResult:
        return self.identify_vectors(to_body_vectors(self._params, uv))[0]
