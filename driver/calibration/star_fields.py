"""Per-field tracker attitudes from identified stars, and the calibration input file of a run.

A run's calibration input (``gyrostar replay LOG --export calib``) is one ``.npz``:

=============  =========  ==========================================================
array          shape      meaning
=============  =========  ==========================================================
``t``          (N,)       gyro sample time stamps, s (host clock, the gyro's own stamps)
``rate``       (N, 3)     gyro rates, rad/s, gyro axes, as read (no calibration applied)
``field``      (M,)       field (frame) number of each identified star, 0..K−1
``uv``         (M, 2)     measured centroid [column, row], px (thresholded CoG refined by
                          the smeared-PSF fit)
``uv_sigma``   (M,)       the centroid's 1σ per axis, px (the fit's CRLB; NaN: a plain CoG)
``ref``        (M, 3)     the star's catalog unit vector, ICRS
``star_id``    (M,)       catalog id
``t_cam``      (K,)       exposure mid-time of each field, s (host clock)
``q_cam``      (K, 4)     QUEST attitude of each field [x, y, z, w], ICRS → camera,
                          through the camera model in ``camera``
``camera``     (10,)      ``CameraModel.as_array()`` used for ``q_cam``
=============  =========  ==========================================================

``camera`` reads ``field``, ``uv``, ``ref`` (and ``star_id``, ``uv_sigma`` for its weights);
``alignment`` and ``gyro-scale --method slew`` read
``t``, ``rate``, ``t_cam``, ``q_cam`` — recomputed by :func:`field_attitudes` through the
calibrated camera when the target calibration file already holds a [camera] table.
"""

from __future__ import annotations

import numpy as np

ARCSEC = np.pi / 180.0 / 3600.0


def field_attitudes(field: np.ndarray, uv: np.ndarray, ref: np.ndarray, camera, n_fields: int | None = None,
                    sigma_px: float = 0.1, min_stars: int = 3, uv_sigma=None) -> tuple[np.ndarray, np.ndarray]:
    """QUEST attitude (ICRS → camera) of every field with ≥ ``min_stars`` stars, each star
    weighted by ``1/σ²``: ``uv_sigma`` (M,) px per observation (NaN or ≤ 0: the median of the
    usable ones, as the camera fit takes them; ``sigma_px`` when none is) with the floor of one
    centroid (:data:`~gyrostar.calibration.intrinsics.OBS_FLOOR_PX`) added, or ``sigma_px`` for
    every star.

    Returns ``(ok (K,) bool, q (K, 4))``; rows of fields without enough stars are zero."""
    from ..core.quest import quest

    field = np.asarray(field, np.int64)
    k = int(n_fields if n_fields is not None else (field.max() + 1 if len(field) else 0))
    q = np.zeros((k, 4))
    ok = np.zeros(k, bool)
    if not len(field):
        return ok, q
    body = camera.unproject(np.asarray(uv, np.float64))
    ref = np.ascontiguousarray(ref, np.float64)
    if uv_sigma is None:
        sig = np.full(len(field), sigma_px)
    else:
        from .intrinsics import OBS_FLOOR_PX, fill_unknown_sigma

        sig = fill_unknown_sigma(uv_sigma)
        if sig is None:
            sig = np.full(len(field), sigma_px)
        sig = np.sqrt(sig ** 2 + OBS_FLOOR_PX ** 2)
    w_obs = 1.0 / (sig / camera.focal_length_px) ** 2
    order = np.argsort(field, kind="stable")
    bounds = np.searchsorted(field[order], np.arange(k + 1))
    for f in range(k):
        idx = order[bounds[f]:bounds[f + 1]]
        if len(idx) < min_stars:
            continue
        q[f], _ = quest(np.ascontiguousarray(body[idx]), np.ascontiguousarray(ref[idx]),
                        np.ascontiguousarray(w_obs[idx]))
        ok[f] = True
    return ok, q


def load_slew_input(path, cal=None, min_stars: int = 3):
    """``(t, rate, t_cam, q_cam, note)`` from a calibration input ``.npz`` for the slew fits.

    When the file holds the identified stars (``field``, ``uv``, ``ref``) and ``cal`` has a
    [camera] table, the field attitudes are recomputed through that calibrated camera (a
    principal-point or distortion error of the run's camera would otherwise bend them)."""
    from .report import read_npz

    z = read_npz(path, ("t", "rate", "t_cam", "q_cam"))
    t, rate, t_cam, q_cam = z["t"], z["rate"], z["t_cam"], z["q_cam"]
    stars = {k: z[k] for k in ("field", "uv", "ref", "camera", "uv_sigma") if k in z}
    note = "attitudes as exported"
    if cal is not None and cal.camera is not None and {"field", "uv", "ref", "camera"} <= set(stars):
        from ..camera import CameraModel
        from .calfile import camera_model

        c = stars["camera"]
        nominal = CameraModel(float(c[0]) * 1e-5, 1e-5, int(c[8]), int(c[9]), float(c[1]), float(c[2]))
        cam = camera_model(cal, nominal)
        ok, q = field_attitudes(stars["field"], stars["uv"], stars["ref"], cam, len(t_cam), min_stars=min_stars,
                                uv_sigma=stars.get("uv_sigma"))
        t_cam, q_cam = t_cam[ok], q[ok]
        note = "attitudes recomputed through the calibrated [camera]"
    keep = np.linalg.norm(q_cam, axis=1) > 0.5
    return t, rate, t_cam[keep], q_cam[keep], note
