"""Synthetic star fields for star-identification Monte Carlo (no rendering).

A :class:`Sky` is a catalog (deeper than the sensor limit, so magnitude noise can bring
stars in and out; entries closer than ``duplicate_arcsec`` are one star listed twice and
keep only the brighter) with a voxel grid for cone queries. :meth:`Sky.observe` projects its
stars through a camera at attitude ``q`` (ICRS → body), adds Gaussian centroid noise
(px, per axis) and magnitude noise, keeps stars whose noisy V is within the sensor limit,
merges spots closer than ``blend_px`` (an unresolved pair is one centroid, whatever the
brightness of its members), adds false stars uniformly over the sensor (merged likewise
when they land on a star) and sorts by brightness. Truth is the
catalog id of every centroid (-1 for a false star).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from ..attitude import quat_to_dcm
from ..camera import project_many
from ..errors import ConfigError
from ..starid.index import cone_query, n_brighter, select_navigation_stars, voxel_grid


@dataclasses.dataclass(frozen=True)
class Frame:
    """One synthetic image: centroids ``uv`` (n, 2) [col, row] px, brightest first;
    ``mag`` (n,) observed V; ``truth`` (n,) catalog id or -1 (false star); ``q`` (4,) truth; ``alt`` (n,) the id of a
    second star blended into the same spot (-1 if none)."""

    uv: np.ndarray
    mag: np.ndarray
    truth: np.ndarray
    q: np.ndarray
    alt: np.ndarray | None = None


class Sky:
    """A catalog with a voxel grid (``catalog``: :class:`gyrostar.catalog.StarCatalog`)."""

    def __init__(self, catalog, vox_h: float = 0.05, blend_px: float = 3.0, duplicate_arcsec: float = 5.0):
        self.catalog = catalog
        self.blend_px = blend_px
        # entries closer than a few arcsec are one star listed twice (Gaia/Hipparcos duplicates)
        keep = select_navigation_stars(catalog.vectors, 0, 0.0, math.radians(duplicate_arcsec / 3600.0))
        self.vectors = np.ascontiguousarray(catalog.vectors[keep])
        self.vmag = np.ascontiguousarray(catalog.vmag[keep])
        self.ids = np.ascontiguousarray(catalog.ids[keep])
        self.vox_h = vox_h
        self.vox_g, self.vox_start, self.vox_stars = voxel_grid(self.vectors, vox_h)
        self.vox_vec = np.ascontiguousarray(self.vectors[self.vox_stars])

    def cone(self, center, radius: float, mag_max: float) -> np.ndarray:
        return cone_query(self.vox_vec, self.vox_stars, self.vox_start, self.vox_h, self.vox_g,
                          np.asarray(center, dtype=np.float64), float(radius), n_brighter(self.vmag, float(mag_max)))

    def observe(self, camera, q, mag_limit: float, pos_noise_px: float, mag_noise: float, n_false: int,
                rng: np.random.Generator) -> Frame:
        """The centroids the sensor reports at attitude ``q``."""
        if pos_noise_px < 0 or mag_noise < 0 or n_false < 0:
            raise ConfigError("noise levels and the false-star count must be ≥ 0")
        params = camera.as_array()
        a = quat_to_dcm(np.asarray(q, dtype=np.float64))
        radius = math.atan(0.5 * math.hypot(camera.width_px, camera.height_px) / camera.focal_length_px)
        near = self.cone(a[2], radius + 1e-3, mag_limit + 5.0 * mag_noise + 1e-9)
        body = self.vectors[near] @ a.T
        uv, _ = project_many(params, np.ascontiguousarray(body))
        near, uv = near[~np.isnan(uv[:, 0])], uv[~np.isnan(uv[:, 0])]
        w, h = camera.width_px, camera.height_px
        # spots closer than blend_px are one spot, whatever their brightness
        order = np.argsort(self.vmag[near], kind="stable")
        uv, mag, truth, alt = blend(uv[order], self.vmag[near][order], self.ids[near][order], self.blend_px)
        n = uv.shape[0]
        if mag_noise > 0:
            mag = mag + rng.normal(0.0, mag_noise, n)
        if pos_noise_px > 0:
            uv = uv + rng.normal(0.0, pos_noise_px, uv.shape)
        on = ((mag <= mag_limit) & (uv[:, 0] >= -0.5) & (uv[:, 0] < w - 0.5)
              & (uv[:, 1] >= -0.5) & (uv[:, 1] < h - 0.5))
        uv, mag, truth, alt = uv[on], mag[on], truth[on], alt[on]
        if n_false:
            fuv = np.column_stack([rng.uniform(-0.5, w - 0.5, n_false), rng.uniform(-0.5, h - 0.5, n_false)])
            fmag = rng.uniform(mag_limit - 3.0, mag_limit, n_false)
            none = -np.ones(n_false, dtype=np.int64)
            order = np.argsort(np.concatenate([mag, fmag]), kind="stable")
            uv, mag, truth, alt = blend(np.vstack([uv, fuv])[order], np.concatenate([mag, fmag])[order],
                                        np.concatenate([truth, none])[order], self.blend_px,
                                        np.concatenate([alt, none])[order])
        return Frame(np.ascontiguousarray(uv), mag, truth, np.asarray(q, dtype=np.float64), alt)


def blend(uv: np.ndarray, mag: np.ndarray, truth: np.ndarray, blend_px: float, alt: np.ndarray | None = None):
    """Merge spots closer than ``blend_px`` (input brightest first): one centroid at the flux-
    weighted position, the summed flux, the truth id of the brightest real star in it and
    (``alt``) of the next real one, -1 if none: naming either is a correct identification."""
    n = uv.shape[0]
    alt = -np.ones(n, dtype=np.int64) if alt is None else alt.copy()
    if n < 2 or blend_px <= 0:
        return uv, mag, truth, alt
    flux = 10.0 ** (-0.4 * mag)
    uv = uv.copy()
    truth = truth.copy()
    keep = np.ones(n, dtype=bool)
    for i in range(1, n):
        d = np.hypot(uv[:i, 0] - uv[i, 0], uv[:i, 1] - uv[i, 1])
        d[~keep[:i]] = np.inf
        j = int(np.argmin(d))
        if d[j] < blend_px:
            keep[i] = False
            uv[j] = (flux[j] * uv[j] + flux[i] * uv[i]) / (flux[j] + flux[i])
            flux[j] += flux[i]
            if truth[j] < 0:
                truth[j] = truth[i]
            elif alt[j] < 0:
                alt[j] = truth[i]
    mag = -2.5 * np.log10(flux[keep])
    order = np.argsort(mag, kind="stable")
    return uv[keep][order], mag[order], truth[keep][order], alt[keep][order]


def score(result_ids: np.ndarray, truth: np.ndarray, alt: np.ndarray | None = None) -> tuple[int, int]:
    """``(n_correct, n_wrong)`` of an identification against truth ids (-1 = false star);
    ``alt``: a second acceptable id per spot (blended pair)."""
    got = result_ids >= 0
    ok = result_ids == truth
    if alt is not None:
        ok |= (result_ids == alt) & (alt >= 0)
    correct = int(np.count_nonzero(got & ok))
    wrong = int(np.count_nonzero(got & ~ok))
    return correct, wrong


def camera_for_fov(fov_deg: float, n_px: int, pitch_m: float = 15e-6):
    """Square pinhole camera with ``n_px`` pixels across a full field of ``fov_deg``."""
    from ..camera import CameraModel

    if not (0.0 < fov_deg < 60.0 and n_px > 1):
        raise ConfigError(f"camera_for_fov needs 0 < fov < 60° and n_px > 1, got {fov_deg}, {n_px}")
    f_px = (n_px / 2.0) / math.tan(math.radians(fov_deg) / 2.0)
    return CameraModel(f_px * pitch_m, pitch_m, n_px, n_px, (n_px - 1) / 2.0, (n_px - 1) / 2.0)
