"""Absent-star check: a solved attitude must not predict bright stars where no spot is.

After a lost-in-space identification, every catalog star the sensor surely detects that
the attitude puts on the sensor should have a spot near its predicted position. "Surely
detected": V at least ``margin_mag`` brighter than both the sensor's limiting magnitude
(the index's navigation limit, ``StarIndex.nav_limit``) and the faintest star the
identification labelled (the image shows that faint a star, and a star ``margin_mag``
brighter is seen whatever the magnitude noise). A wrong attitude that
happens to fit a few spots looks at another patch of sky, whose own bright stars then fall
where the image has nothing: one such star rejects it.

Only the catalog side decides, so false spots (hot pixels, glints) cannot trigger the
check, and it needs no measured magnitudes. A predicted star within ``edge_px`` of the
sensor's border is not asked for (its spot may be cut), nor one within ``near_rad`` of any
spot (a blend pulls a centroid off its star). Units: directions are unit vectors in the
body frame (camera) and ICRS; ``q`` is ICRS → body, [x, y, z, w].
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..attitude import quat_to_dcm
from ..camera import P_H, P_W, project_point
from .index import cone_query, n_brighter

MARGIN_MAG = 1.0     # mag: a star this much brighter than the faintest seen is surely seen (5σ of 0.2 mag)
BLEND_PX = 3.0       # px: a spot this far off its star (a blend) still counts as the star's spot
EDGE_PX = 4.0        # px: a star predicted this close to the border may be cut: not asked for


@njit(cache=True)
def absent_stars(q, b, match, params, vectors, vmag, vox_vec, vox_stars, vox_start, vox_h, vox_g, fov_radius,
                 mag_limit, margin_mag, near_rad, edge_px):
    """How many surely-detected catalog stars attitude ``q`` puts on the sensor with no
    spot within ``near_rad`` (rad) of them.

    ``b`` (n, 3) the spots' body directions, ``match`` (n,) their labels (index rows, -1
    none: only the labels' magnitudes are read), ``params`` the camera
    (:meth:`gyrostar.camera.CameraModel.as_array`), the rest the :class:`StarIndex` arrays
    (stars sorted by V) and the camera's half-diagonal ``fov_radius`` (rad). 0 when nothing
    is labelled."""
    v_faint = -np.inf
    for i in range(match.shape[0]):
        if match[i] >= 0 and vmag[match[i]] > v_faint:
            v_faint = vmag[match[i]]
    if v_faint == -np.inf:
        return 0
    n_max = n_brighter(vmag, min(mag_limit, v_faint) - margin_mag)
    if n_max == 0:
        return 0
    a = quat_to_dcm(q)
    centre = np.empty(3)
    for k in range(3):
        centre[k] = a[2, k]            # the boresight in ICRS
    cos_near = np.cos(near_rad)
    w = params[P_W]
    h = params[P_H]
    absent = 0
    v = np.empty(3)
    for s in cone_query(vox_vec, vox_stars, vox_start, vox_h, vox_g, centre, fov_radius, n_max):
        for k in range(3):
            v[k] = a[k, 0] * vectors[s, 0] + a[k, 1] * vectors[s, 1] + a[k, 2] * vectors[s, 2]
        u, r, on = project_point(params, v)
        if not on or u < edge_px - 0.5 or r < edge_px - 0.5 or u > w - 0.5 - edge_px or r > h - 0.5 - edge_px:
            continue
        seen = False
        for i in range(b.shape[0]):
            if b[i, 0] * v[0] + b[i, 1] * v[1] + b[i, 2] * v[2] >= cos_near:
                seen = True
                break
        if not seen:
            absent += 1
    return absent
