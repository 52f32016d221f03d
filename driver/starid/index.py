"""Catalog index for star identification: navigation stars, star pairs with a k-vector,
per-star neighbour tables and a voxel grid for cone queries. Built once, cached as a file.

* Stars: the catalog to ``mag_limit`` less the fainter member of every pair closer than
  ``DOUBLE_SEP_DEG`` (unresolved doubles); all of them can label an image once the
  attitude is known.
* Navigation stars (``is_nav``): those of them to ``nav_mag_limit`` (all by default; a
  sensor whose magnitudes scatter by σ_m sees stars ~3σ_m fainter than its limit now and
  then, so an index may hold such stars to label spots while only the stars to the
  sensor's limit form patterns), optionally thinned so that they are spread
  evenly over the sky — walking from the brightest down, a star is kept only if fewer
  than ``per_field`` kept stars lie within ``thin_radius`` of it (0 keeps all).
* Star pairs: every pair of navigation stars closer than ``max_sep`` (rad, the sensor's
  diagonal field), sorted by their angle θ (rad) with a k-vector on θ
  (:mod:`gyrostar.starid.kvector`).
* Neighbour table: for each star the partners of its pairs (CSR ``nb_start``/``nb_idx``).
* Voxels: the cube [-1, 1]³ cut into cells of side ``vox_h``; each cell lists its stars,
  so a cone of radius ρ around a direction visits only the cells around it.

Everything is ICRS. ``load_index(catalog, mag_limit, max_sep_deg, per_field=.., label_depth_mag=..)``
builds or reads
``<cache_dir("starid")>/index_<catalog>_m<mag>_e<epoch>_f<sep>_n<per_field>_l<depth>_v<version>.npz``.
"""

from __future__ import annotations

import dataclasses
import math
import os
import tempfile
from pathlib import Path

import numpy as np
from numba import njit

from ..errors import ConfigError
from ..paths import cache_dir
from . import kvector

INDEX_VERSION = 8
DOUBLE_SEP_DEG = 0.02  # 72″: closer pairs are one spot for every preset sensor (blend ≥ 3 px ≥ 84″)


@dataclasses.dataclass(frozen=True, eq=False)
class StarIndex:
    """Navigation stars (sorted by V) with pair, neighbour and voxel tables. Angles in rad."""

    catalog: str
    mag_limit: float
    epoch: float
    max_sep: float
    per_field: int
    is_nav: np.ndarray       # bool (n,) navigation star (in the pair table)
    ids: np.ndarray          # int64 (n,) catalog ids (HIP / Gaia source id)
    vectors: np.ndarray      # float64 (n, 3) ICRS unit vectors
    vmag: np.ndarray         # float64 (n,) V
    pair_theta: np.ndarray   # float64 (p,) ascending
    pair_a: np.ndarray       # int32 (p,) navigation-star index
    pair_b: np.ndarray       # int32 (p,)
    kv: np.ndarray           # int64 (p,) k-vector on pair_theta
    kv_m: float
    kv_q: float
    nb_start: np.ndarray     # int64 (n+1,) CSR into nb_idx
    nb_idx: np.ndarray       # int32 (2p,) partners, per star
    vox_h: float
    vox_g: int
    vox_start: np.ndarray    # int64 (g³+1,)
    vox_stars: np.ndarray    # int32 (n,)
    vox_vec: np.ndarray      # float64 (n, 3) vectors in voxel order
    nav_mag_limit: float = math.inf   # V of the faintest navigation star if fainter stars are held (inf: all navigate)

    @property
    def nav_limit(self) -> float:
        """V of the faintest star a navigation star may be: the sensor's limit the index was
        built for (its stars may go deeper, to label spots)."""
        return min(self.mag_limit, self.nav_mag_limit)

    def __len__(self) -> int:
        return int(self.ids.shape[0])

    @property
    def n_pairs(self) -> int:
        return int(self.pair_theta.shape[0])

    def neighbours(self, i: int) -> np.ndarray:
        """Navigation-star indexes within ``max_sep`` of star ``i``."""
        return self.nb_idx[self.nb_start[i]:self.nb_start[i + 1]]

    def cone(self, center: np.ndarray, radius: float, mag_max: float = np.inf) -> np.ndarray:
        """Indexes of the stars within ``radius`` (rad) of ``center`` (ICRS) and V ≤ ``mag_max``."""
        c = np.asarray(center, dtype=np.float64)
        return cone_query(self.vox_vec, self.vox_stars, self.vox_start, self.vox_h, self.vox_g,
                          c / np.linalg.norm(c), float(radius), n_brighter(self.vmag, float(mag_max)))


def select_navigation_stars(vectors: np.ndarray, per_field: int, thin_radius: float,
                            double_sep: float = 0.0) -> np.ndarray:
    """Indexes (ascending) of the navigation stars of a catalog sorted by V.

    A star with a brighter star closer than ``double_sep`` (rad) is dropped (an unresolved
    double: the sensor sees one spot, centred near the brighter). Then, brightest first,
    a star is kept only while fewer than ``per_field`` kept stars lie within
    ``thin_radius`` (``per_field`` 0: no thinning).
    """
    from scipy.spatial import cKDTree

    n = vectors.shape[0]
    alive = np.ones(n, dtype=bool)
    if double_sep > 0.0:
        close = cKDTree(vectors).query_pairs(2.0 * math.sin(double_sep / 2.0), output_type="ndarray")
        if close.size:
            alive[np.max(close, axis=1)] = False
    if per_field <= 0:
        return np.flatnonzero(alive)
    chord = 2.0 * math.sin(thin_radius / 2.0)
    near = cKDTree(vectors).query_ball_point(vectors, chord, workers=1)
    kept = np.zeros(n, dtype=bool)
    for i in range(n):
        if not alive[i]:
            continue
        nb = near[i]
        if np.count_nonzero(kept[nb]) < per_field:
            kept[i] = True
    return np.flatnonzero(kept)


def star_pairs(vectors: np.ndarray, max_sep: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """All pairs closer than ``max_sep`` (rad): ``(theta ascending, a, b)``."""
    from scipy.spatial import cKDTree

    chord = 2.0 * math.sin(max_sep / 2.0)
    pairs = cKDTree(vectors).query_pairs(chord, output_type="ndarray")
    a = pairs[:, 0].astype(np.int32)
    b = pairs[:, 1].astype(np.int32)
    dots = np.einsum("ij,ij->i", vectors[a], vectors[b])
    theta = np.arccos(np.clip(dots, -1.0, 1.0))
    order = np.argsort(theta, kind="stable")
    return theta[order], a[order], b[order]


def neighbour_table(n: int, a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """CSR (start, idx) of each star's pair partners."""
    src = np.concatenate([a, b])
    dst = np.concatenate([b, a])
    order = np.argsort(src, kind="stable")
    start = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(np.bincount(src, minlength=n), out=start[1:])
    return start, np.ascontiguousarray(dst[order], dtype=np.int32)


def voxel_grid(vectors: np.ndarray, h: float) -> tuple[int, np.ndarray, np.ndarray]:
    """Voxel CSR of unit vectors: ``(g, start (g³+1,), stars)``; inside a cell the stars keep
    their input order (brightest first for a catalog sorted by V)."""
    g = int(math.ceil(2.0 / h)) + 1
    cell = _voxel_cells(vectors, h, g)
    order = np.argsort(cell, kind="stable")
    start = np.zeros(g ** 3 + 1, dtype=np.int64)
    np.cumsum(np.bincount(cell, minlength=g ** 3), out=start[1:])
    return g, start, order.astype(np.int32)


def _voxel_cells(vectors, h, g):
    ijk = np.clip(np.floor((vectors + 1.0) / h).astype(np.int64), 0, g - 1)
    return (ijk[:, 0] * g + ijk[:, 1]) * g + ijk[:, 2]


@njit(cache=True)
def voxel_span(center, chord, h, g):
    """The voxel index ranges ``(lo0, hi0, lo1, hi1, lo2, hi2)`` (inclusive) that hold every
    unit vector within ``chord`` of ``center`` (grid of ``g`` cells of edge ``h`` per axis)."""
    lo0 = max(0, int(np.floor((center[0] - chord + 1.0) / h)))
    hi0 = min(g - 1, int(np.floor((center[0] + chord + 1.0) / h)))
    lo1 = max(0, int(np.floor((center[1] - chord + 1.0) / h)))
    hi1 = min(g - 1, int(np.floor((center[1] + chord + 1.0) / h)))
    lo2 = max(0, int(np.floor((center[2] - chord + 1.0) / h)))
    hi2 = min(g - 1, int(np.floor((center[2] + chord + 1.0) / h)))
    return lo0, hi0, lo1, hi1, lo2, hi2


@njit(cache=True)
def any_within(vox_vec, vox_start, h, g, center, radius):
    """Whether any vector of the voxel grid (``vox_vec`` in cell order, ``vox_start`` each
    cell's first) lies within ``radius`` (rad) of unit ``center``; stops at the first."""
    cosr = np.cos(radius)
    lo0, hi0, lo1, hi1, lo2, hi2 = voxel_span(center, 2.0 * np.sin(radius / 2.0), h, g)
    for i in range(lo0, hi0 + 1):
        for j in range(lo1, hi1 + 1):
            base = (i * g + j) * g
            for p in range(vox_start[base + lo2], vox_start[base + hi2 + 1]):
                if vox_vec[p, 0] * center[0] + vox_vec[p, 1] * center[1] + vox_vec[p, 2] * center[2] >= cosr:
                    return True
    return False


@njit(cache=True)
def cone_query(vox_vec, vox_stars, vox_start, h, g, center, radius, n_max):
    """Indexes (ascending) of the stars within ``radius`` of unit ``center`` among the first
    ``n_max`` (stars are sorted by V, so that is a magnitude limit).

    ``vox_vec`` are the unit vectors in voxel order (each cell's stars contiguous, brightest
    first), so a cell is one sequential read and the scan stops at the limit."""
    chord = 2.0 * np.sin(radius / 2.0)
    cosr = np.cos(radius)
    lo0, hi0, lo1, hi1, lo2, hi2 = voxel_span(center, chord, h, g)
    cap = 64
    out = np.empty(cap, dtype=np.int64)
    n = 0
    c0, c1, c2 = center[0], center[1], center[2]
    for i in range(lo0, hi0 + 1):
        for j in range(lo1, hi1 + 1):
            base = (i * g + j) * g
            for p in range(vox_start[base + lo2], vox_start[base + hi2 + 1]):
                s = vox_stars[p]
                if s >= n_max:
                    continue
                if vox_vec[p, 0] * c0 + vox_vec[p, 1] * c1 + vox_vec[p, 2] * c2 >= cosr:
                    if n == cap:
                        cap *= 2
                        bigger = np.empty(cap, dtype=np.int64)
                        bigger[:n] = out[:n]
                        out = bigger
                    out[n] = s
                    n += 1
    return np.sort(out[:n])


@njit(cache=True)
def n_brighter(vmag, mag_max):
    """How many stars (sorted by V) have V ≤ ``mag_max``."""
    return np.searchsorted(vmag, mag_max, side="right")


MAX_PAIRS = 50_000_000   # star pairs an index may hold (~3 GB while it is built)


def build_index(catalog, max_sep_deg: float, per_field: int = 0, thin_radius_deg: float | None = None,
                vox_h: float = 0.05, double_sep_deg: float = DOUBLE_SEP_DEG,
                nav_mag_limit: float = math.inf) -> StarIndex:
    """Build the index of a :class:`gyrostar.catalog.StarCatalog` (no cache); navigation stars
    only to ``nav_mag_limit`` (V; the fainter stars label spots but form no pattern)."""
    if not (math.isfinite(max_sep_deg) and 0.0 < max_sep_deg < 60.0):
        raise ConfigError(f"index max_sep_deg must be in (0, 60), got {max_sep_deg!r}")
    if per_field < 0:
        raise ConfigError(f"index per_field must be ≥ 0, got {per_field!r}")
    max_sep = math.radians(max_sep_deg)
    thin = math.radians(thin_radius_deg) if thin_radius_deg is not None else max_sep / 2.0
    keep = select_navigation_stars(catalog.vectors, 0, thin, math.radians(double_sep_deg))
    vec = np.ascontiguousarray(catalog.vectors[keep])
    bright = np.flatnonzero(catalog.vmag[keep] <= nav_mag_limit)
    # the limit as the faintest star within it (as mag_limit is the faintest star of all)
    nav_v = float(catalog.vmag[keep][bright[-1]]) if math.isfinite(nav_mag_limit) and bright.size else math.inf
    nav = bright[select_navigation_stars(vec[bright], per_field, thin)]
    # a uniform sky of n stars has n²·(1 − cos θ)/4 pairs within θ; each costs ~60 B while built
    pairs = len(nav) ** 2 * (1.0 - math.cos(max_sep)) / 4.0
    if pairs > MAX_PAIRS:
        raise ConfigError(f"a star index of {catalog.name} to V {float(catalog.vmag[-1]):.1f} with pairs to "
                          f"{max_sep_deg:.1f}° would hold ~{pairs / 1e6:.0f} M pairs (~{pairs * 60 / 1e9:.0f} GB to "
                          f"build, limit {MAX_PAIRS / 1e6:.0f} M): lower the limiting magnitude ([loop] mag_limit, "
                          f"--mag-limit) or thin the navigation stars (--per-field)")
    theta, a, b = star_pairs(vec[nav], max_sep)
    a = nav[a].astype(np.int32)
    b = nav[b].astype(np.int32)
    if theta.shape[0] < 2:
        raise ConfigError(f"catalog {catalog.name} has fewer than 2 star pairs within {max_sep_deg}°")
    kv, m, q = kvector.build(theta)
    nb_start, nb_idx = neighbour_table(vec.shape[0], a, b)
    g, vstart, vstars = voxel_grid(vec, vox_h)
    mag_limit = float(catalog.vmag[-1]) if len(catalog.vmag) else 0.0
    is_nav = np.zeros(vec.shape[0], dtype=bool)
    is_nav[nav] = True
    return StarIndex(catalog.name, mag_limit, float(catalog.epoch), max_sep, int(per_field), is_nav,
                     np.ascontiguousarray(catalog.ids[keep]), vec, np.ascontiguousarray(catalog.vmag[keep]),
                     theta, a, b, kv, m, q, nb_start, nb_idx, float(vox_h), g, vstart, vstars,
                     np.ascontiguousarray(vec[vstars]), nav_v)


def index_path(catalog: str, mag_limit: float, epoch: float, max_sep_deg: float, per_field: int,
               label_depth_mag: float = 0.0) -> Path:
    """Cache file of an index."""
    return cache_dir("starid") / (f"index_{catalog}_m{mag_limit:.3f}_e{epoch:.3f}_f{max_sep_deg:.4f}"
                                  f"_n{per_field}_l{label_depth_mag:.2f}_v{INDEX_VERSION}.npz")


def load_index(catalog: str = "hip2", mag_limit: float = 6.5, max_sep_deg: float = 14.2,
               per_field: int = 0, epoch: float = 2025.0, label_depth_mag: float = 0.0) -> StarIndex:
    """The index of ``catalog`` for pairs within ``max_sep_deg``, cached: navigation stars to
    ``mag_limit`` (the sensor's limit), and stars that only label spots ``label_depth_mag``
    deeper (0: none)."""
    from ..catalog import deepest_limit, load_catalog

    if not (math.isfinite(label_depth_mag) and label_depth_mag >= 0.0):
        raise ConfigError(f"index label_depth_mag must be ≥ 0, got {label_depth_mag!r}")
    path = index_path(catalog, float(mag_limit), float(epoch), float(max_sep_deg), int(per_field),
                      float(label_depth_mag))
    if path.exists():
        try:
            with np.load(path) as z:
                f = {k: z[k] for k in z.files}
            return StarIndex(catalog, float(f["mag_limit"]), float(f["epoch"]), float(f["max_sep"]),
                             int(f["per_field"]), f["is_nav"], f["ids"], f["vectors"], f["vmag"], f["pair_theta"],
                             f["pair_a"], f["pair_b"], f["kv"], float(f["kv_m"]), float(f["kv_q"]),
                             f["nb_start"], f["nb_idx"], float(f["vox_h"]), int(f["vox_g"]),
                             f["vox_start"], f["vox_stars"], f["vox_vec"], float(f["nav_mag_limit"]))
        except (OSError, KeyError, ValueError):
            path.unlink(missing_ok=True)  # corrupt cache: rebuild below
    from ..logs import stage

    with stage(f"building the star index ({catalog} to V {mag_limit:.1f}, pairs within {max_sep_deg:.1f}°): once per "
               f"catalog and camera; cached in {path.parent}"):
        depth = (deepest_limit(catalog, float(mag_limit) + label_depth_mag) if label_depth_mag > 0.0
                 else float(mag_limit))
        cat = load_catalog(catalog, depth, float(epoch))
        idx = build_index(cat, float(max_sep_deg), int(per_field), nav_mag_limit=float(mag_limit))
    fd, tmp = tempfile.mkstemp(dir=path.parent, suffix=".npz")
    os.close(fd)
    arrays = {f.name: getattr(idx, f.name) for f in dataclasses.fields(idx) if f.name != "catalog"}
    np.savez(tmp, **arrays)
    os.replace(tmp, path)
    return idx
