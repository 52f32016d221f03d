"""FITS WCS (TAN with SIP distortion) of a plate solution, written with astropy.

Pixel axes: FITS axis 1 = column ``u``, axis 2 = row ``v``; CRPIX is 1-based (``cx + 1``,
``cy + 1``). The camera model (:mod:`gyrostar.camera`, radial: ``u = cx + f·xn·(1 + k1 r²)``)
maps a direction to a distorted pixel; SIP's ``A``/``B`` polynomials (order ``SIP_ORDER``, in
the distorted offsets ``U = u − cx``, ``V = v − cy``) give the undistorted offsets
``U' = f·xn``, and ``AP``/``BP`` the inverse, both least-squares fits over a grid across the
sensor (the fit's worst error is returned). The CD matrix turns undistorted offsets into the
standard coordinates (ξ east, η north, °) of the tangent plane at the boresight: with camera
axes x, y and the boresight's east/north unit vectors e, n (ICRS),
``CD = (180/π)/f · [[e·x, e·y], [n·x, n·y]]`` (exact on the tangent plane).
"""

from __future__ import annotations

import math

import numpy as np

SIP_ORDER = 5
GRID = 25


def _monomials(u: np.ndarray, v: np.ndarray, order: int, lowest: int) -> tuple[np.ndarray, list[tuple[int, int]]]:
    terms = [(p, q) for p in range(order + 1) for q in range(order + 1 - p) if p + q >= lowest]
    return np.column_stack([u ** p * v ** q for p, q in terms]), terms


def _fit_poly(u, v, du, dv, order, lowest, scale):
    mat, terms = _monomials(u / scale, v / scale, order, lowest)
    ca, *_ = np.linalg.lstsq(mat, du, rcond=None)
    cb, *_ = np.linalg.lstsq(mat, dv, rcond=None)
    err = float(np.max(np.hypot(mat @ ca - du, mat @ cb - dv)))
    # coefficients of the unscaled monomials u^p v^q
    k = np.array([scale ** -(p + q) for p, q in terms])
    return terms, ca * k, cb * k, err


def tan_cd(q_icrs_to_camera, focal_length_px: float) -> tuple[np.ndarray, float, float]:
    """TAN CD matrix (deg/px, 2×2) and boresight (RA, Dec) in degrees of attitude ``q``
    (ICRS → camera) for a focal length in pixels (module docstring)."""
    from ..attitude import quat_to_dcm

    a = quat_to_dcm(np.asarray(q_icrs_to_camera, dtype=np.float64))
    z = a[2]
    ra = math.atan2(z[1], z[0]) % (2 * math.pi)
    dec = math.asin(max(-1.0, min(1.0, z[2])))
    east = np.array([-math.sin(ra), math.cos(ra), 0.0])
    north = np.array([-math.sin(dec) * math.cos(ra), -math.sin(dec) * math.sin(ra), math.cos(dec)])
    k = math.degrees(1.0) / focal_length_px
    cd = k * np.array([[a[0] @ east, a[1] @ east], [a[0] @ north, a[1] @ north]])
    return cd, math.degrees(ra), math.degrees(dec)


def wcs_header(q_icrs_to_camera, focal_length_px: float, k1: float, cx: float, cy: float, width: int, height: int,
               sip_order: int = SIP_ORDER):
    """``(astropy.io.fits.Header, max_fit_error_px)`` of the solution (module docstring)."""
    from astropy.io import fits

    from ..camera import CameraModel, unproject_many

    cd, ra_deg, dec_deg = tan_cd(q_icrs_to_camera, focal_length_px)
    h = fits.Header()
    h["WCSAXES"] = 2
    h["CTYPE1"], h["CTYPE2"] = ("RA---TAN-SIP", "TAN projection, SIP distortion"), ("DEC--TAN-SIP", "")
    h["CUNIT1"], h["CUNIT2"] = "deg", "deg"
    h["CRVAL1"], h["CRVAL2"] = (ra_deg, "boresight RA (deg)"), (dec_deg, "boresight Dec (deg)")
    h["CRPIX1"], h["CRPIX2"] = (cx + 1.0, "principal point column (1-based)"), (cy + 1.0, "principal point row")
    h["CD1_1"], h["CD1_2"], h["CD2_1"], h["CD2_2"] = (float(v) for v in cd.ravel())
    h["RADESYS"] = "ICRS"
    h["IMAGEW"], h["IMAGEH"] = width, height
    # forward SIP: distorted offsets → undistorted offsets
    uu, vv = np.meshgrid(np.linspace(-0.5, width - 0.5, GRID), np.linspace(-0.5, height - 0.5, GRID))
    uv = np.column_stack([uu.ravel(), vv.ravel()])
    cam = CameraModel(focal_length_px * 1e-5, 1e-5, width, height, cx, cy, k1).as_array()
    body = unproject_many(cam, np.ascontiguousarray(uv))
    U, V = uv[:, 0] - cx, uv[:, 1] - cy
    Uu, Vu = focal_length_px * body[:, 0] / body[:, 2], focal_length_px * body[:, 1] / body[:, 2]
    scale = 0.5 * math.hypot(width, height)
    terms, ca, cb, err_f = _fit_poly(U, V, Uu - U, Vu - V, sip_order, 2, scale)
    h["A_ORDER"], h["B_ORDER"] = sip_order, sip_order
    for (p, qq), va, vb in zip(terms, ca, cb):
        h[f"A_{p}_{qq}"] = float(va)
        h[f"B_{p}_{qq}"] = float(vb)
    # inverse SIP: undistorted offsets → distorted offsets (terms from order 1: AP_1_0 etc.)
    terms_i, cai, cbi, err_i = _fit_poly(Uu, Vu, U - Uu, V - Vu, sip_order, 1, scale)
    h["AP_ORDER"], h["BP_ORDER"] = sip_order, sip_order
    for (p, qq), va, vb in zip(terms_i, cai, cbi):
        h[f"AP_{p}_{qq}"] = float(va)
        h[f"BP_{p}_{qq}"] = float(vb)
    return h, max(err_f, err_i)
