"""Pinhole camera with Brown–Conrady distortion: body-frame directions ↔ pixel coordinates.

Frames (see :mod:`gyrostar.attitude`): body = camera frame, +z boresight, +x along
increasing column, +y along increasing row. Pixel coordinates are ``uv = [col, row]``
(float, pixel centres at integers; the sensor covers ``-0.5 ≤ u < width - 0.5`` and
``-0.5 ≤ v < height - 0.5``).

Model, for a body-frame direction ``(X, Y, Z)`` with ``Z > 0``::

    xn = X / Z,  yn = Y / Z                       (normalised; image-plane x = F·xn, metres)
    r² = xn² + yn²,  k = 1 + k1 r² + k2 r⁴ + k3 r⁶
    xd = xn k + 2 p1 xn yn + p2 (r² + 2 xn²)
    yd = yn k + p1 (r² + 2 yn²) + 2 p2 xn yn
    u = cx + f_px xd,  v = cy + f_px yd,          f_px = F / pitch

``unproject`` inverts the distortion by fixed-point iteration (converges to < 1e-12 for
the distortions of any star-tracker lens, |Δ| ≪ 1).

Hot paths use the numba functions on a float64 parameter vector, ``CameraModel.as_array()``::

    params = [f_px, cx_px, cy_px, k1, k2, k3, p1, p2, width_px, height_px]   (index P_*)

``project_point(params, v) -> (u, v, ok)``, ``unproject_point(params, u, v) -> (3,)``,
``project_many(params, vecs) -> (uv, valid)``, ``unproject_many(params, uv) -> (n, 3)``.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from numba import njit

from .errors import ConfigError

P_F, P_CX, P_CY, P_K1, P_K2, P_K3, P_P1, P_P2, P_W, P_H = range(10)
N_PARAMS = 10
_UNDISTORT_ITERS = 30


@njit(cache=True)
def distort(params, xn, yn):
    """Normalised undistorted (xn, yn) → distorted (xd, yd)."""
    k1, k2, k3, p1, p2 = params[P_K1], params[P_K2], params[P_K3], params[P_P1], params[P_P2]
    r2 = xn * xn + yn * yn
    k = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    xd = xn * k + 2.0 * p1 * xn * yn + p2 * (r2 + 2.0 * xn * xn)
    yd = yn * k + p1 * (r2 + 2.0 * yn * yn) + 2.0 * p2 * xn * yn
    return xd, yd


@njit(cache=True)
def undistort(params, xd, yd):
    """Distorted (xd, yd) → normalised undistorted (xn, yn), by fixed-point iteration."""
    k1, k2, k3, p1, p2 = params[P_K1], params[P_K2], params[P_K3], params[P_P1], params[P_P2]
    if k1 == 0.0 and k2 == 0.0 and k3 == 0.0 and p1 == 0.0 and p2 == 0.0:
        return xd, yd
    xn, yn = xd, yd
    for _ in range(_UNDISTORT_ITERS):
        r2 = xn * xn + yn * yn
        k = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
        dx = 2.0 * p1 * xn * yn + p2 * (r2 + 2.0 * xn * xn)
        dy = p1 * (r2 + 2.0 * yn * yn) + 2.0 * p2 * xn * yn
        xn = (xd - dx) / k
        yn = (yd - dy) / k
    return xn, yn


@njit(cache=True)
def project_point(params, v):
    """Body direction ``v`` (3,) → ``(u, v, ok)``: pixel column, row and in-front-and-on-sensor."""
    if v[2] <= 0.0:
        return np.nan, np.nan, False
    xd, yd = distort(params, v[0] / v[2], v[1] / v[2])
    u = params[P_CX] + params[P_F] * xd
    r = params[P_CY] + params[P_F] * yd
    ok = (u >= -0.5) and (u < params[P_W] - 0.5) and (r >= -0.5) and (r < params[P_H] - 0.5)
    return u, r, ok


@njit(cache=True)
def unproject_point(params, u, v):
    """Pixel (column ``u``, row ``v``) → unit body direction (3,)."""
    xn, yn = undistort(params, (u - params[P_CX]) / params[P_F], (v - params[P_CY]) / params[P_F])
    n = math.sqrt(xn * xn + yn * yn + 1.0)
    out = np.empty(3)
    out[0] = xn / n
    out[1] = yn / n
    out[2] = 1.0 / n
    return out


@njit(cache=True)
def project_many(params, vecs):
    """Body directions (n, 3) → ``uv`` (n, 2) [col, row] and ``valid`` (n,) bool."""
    n = vecs.shape[0]
    uv = np.empty((n, 2))
    valid = np.empty(n, dtype=np.bool_)
    for i in range(n):
        u, r, ok = project_point(params, vecs[i])
        uv[i, 0] = u
        uv[i, 1] = r
        valid[i] = ok
    return uv, valid


@njit(cache=True)
def unproject_many(params, uv):
    """Pixel coordinates (n, 2) [col, row] → unit body directions (n, 3)."""
    n = uv.shape[0]
    out = np.empty((n, 3))
    for i in range(n):
        out[i] = unproject_point(params, uv[i, 0], uv[i, 1])
    return out


@dataclasses.dataclass(frozen=True)
class CameraModel:
    """Pinhole + Brown–Conrady camera. Lengths in metres, pixel quantities in pixels."""

    focal_length_m: float
    pixel_pitch_m: float
    width_px: int
    height_px: int
    cx_px: float
    cy_px: float
    k1: float = 0.0
    k2: float = 0.0
    k3: float = 0.0
    p1: float = 0.0
    p2: float = 0.0

    def __post_init__(self) -> None:
        for name in ("focal_length_m", "pixel_pitch_m"):
            val = getattr(self, name)
            if not (math.isfinite(val) and val > 0.0):
                raise ConfigError(f"camera {name} must be a positive number, got {val!r}")
        for name in ("width_px", "height_px"):
            val = getattr(self, name)
            if int(val) != val or val <= 0:
                raise ConfigError(f"camera {name} must be a positive integer, got {val!r}")
        for name in ("cx_px", "cy_px", "k1", "k2", "k3", "p1", "p2"):
            if not math.isfinite(getattr(self, name)):
                raise ConfigError(f"camera {name} must be finite, got {getattr(self, name)!r}")

    @property
    def focal_length_px(self) -> float:
        """Focal length in pixels, F / pitch."""
        return self.focal_length_m / self.pixel_pitch_m

    @property
    def fov_x_deg(self) -> float:
        """Full field of view across the columns (edge to edge, from the principal point)."""
        f = self.focal_length_px
        return math.degrees(math.atan((self.cx_px + 0.5) / f) + math.atan((self.width_px - 0.5 - self.cx_px) / f))

    @property
    def fov_y_deg(self) -> float:
        """Full field of view across the rows (edge to edge, from the principal point)."""
        f = self.focal_length_px
        return math.degrees(math.atan((self.cy_px + 0.5) / f) + math.atan((self.height_px - 0.5 - self.cy_px) / f))

    @property
    def ifov_rad(self) -> float:
        """Angle subtended by one pixel at the principal point (rad)."""
        return 1.0 / self.focal_length_px

    def as_array(self) -> np.ndarray:
        """Parameter vector for the numba functions (see the module docstring)."""
        p = np.empty(N_PARAMS)
        p[P_F], p[P_CX], p[P_CY] = self.focal_length_px, self.cx_px, self.cy_px
        p[P_K1], p[P_K2], p[P_K3], p[P_P1], p[P_P2] = self.k1, self.k2, self.k3, self.p1, self.p2
        p[P_W], p[P_H] = self.width_px, self.height_px
        return p

    def project(self, v_body: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Body directions (n, 3) (any length) → ``uv`` (n, 2) [col, row] and ``valid`` (n,)."""
        vecs = np.ascontiguousarray(np.atleast_2d(v_body), dtype=np.float64)
        if vecs.ndim != 2 or vecs.shape[1] != 3:
            raise ConfigError(f"project expects (n, 3) body vectors, got shape {np.shape(v_body)}")
        return project_many(self.as_array(), vecs)

    def unproject(self, uv: np.ndarray) -> np.ndarray:
        """Pixel coordinates (n, 2) [col, row] → unit body directions (n, 3)."""
        pts = np.ascontiguousarray(np.atleast_2d(uv), dtype=np.float64)
        if pts.ndim != 2 or pts.shape[1] != 2:
            raise ConfigError(f"unproject expects (n, 2) pixel coordinates, got shape {np.shape(uv)}")
        return unproject_many(self.as_array(), pts)


def _xing2012() -> CameraModel:
    # paper 000: F = 100 mm; STAR1000-class sensor 1024×1024, 15 µm (SPEC §3)
    n = 1024
    return CameraModel(0.100, 15e-6, n, n, (n - 1) / 2.0, (n - 1) / 2.0)


def _qian2015() -> CameraModel:
    # paper 001 as read in SPEC §2: 512×512 px over 4°×4° (28.1″/px). f_px from the full
    # field: 256 px = f_px·tan(2°). Pitch 15 µm (STAR1000 class) → F ≈ 110 mm.
    n = 512
    pitch = 15e-6
    f_px = (n / 2.0) / math.tan(math.radians(2.0))
    return CameraModel(f_px * pitch, pitch, n, n, (n - 1) / 2.0, (n - 1) / 2.0)


CAMERA_PRESETS = {"xing2012": _xing2012, "qian2015": _qian2015}


def camera_preset(name: str) -> CameraModel:
    """The camera of a named preset (``xing2012``, ``qian2015``)."""
    try:
        return CAMERA_PRESETS[name]()
    except KeyError:
        raise ConfigError(f"unknown camera preset '{name}' (known: {', '.join(CAMERA_PRESETS)})") from None
