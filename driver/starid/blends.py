"""Blended stars: catalog stars whose spot is not at their catalog place.

A star with another star within ``BLEND_PX`` on the sensor that is at most ``BLEND_DMAG``
fainter makes one spot with it, centred between them (HIP 24020 and 24019, V 5.90 and 5.94,
0.4 px apart, are one spot 0.2 px from either). The tracking loop prefers other stars
(:class:`gyrostar.loop.tracks.StarTracks`); the calibration export leaves such stars out
with a wider radius of its own (its centre of gravity spans the whole window). The
neighbours come from a catalog deeper than the stars checked (``BLEND_DMAG`` below their
limit, or as deep as it goes). Directions are ICRS unit vectors; radii are angles (rad) on
the sky.
"""

from __future__ import annotations

import numpy as np

BLEND_PX = 3.0      # px: a neighbour this close shares the spot (3.5 PSF σ of 0.85 px); the loop's window fit
#                     measured HIP 12086 (a V+1.35 star 4.6 px off) well: dropping it cost 3 % of the at-rest precision
BLEND_DMAG = 3.0    # mag: a neighbour up to this much fainter counts (3 mag: 6 % of the flux)


def blended(stars, deep, radius_rad: float, dmag: float = BLEND_DMAG) -> np.ndarray:
    """(n,) bool over ``stars`` (anything with ``ids``, ``vectors``, ``vmag``: a
    :class:`gyrostar.catalog.StarCatalog` or :class:`gyrostar.starid.index.StarIndex`): another
    star of ``deep`` (same catalog, same ids) lies within ``radius_rad`` and is at most
    ``dmag`` fainter. The same star in ``deep`` (matched by id) does not count."""
    from scipy.spatial import cKDTree

    out = np.zeros(len(stars.ids), bool)
    if not len(stars.ids) or not len(deep.ids):
        return out
    near = cKDTree(deep.vectors).query_ball_point(stars.vectors, 2.0 * np.sin(radius_rad / 2.0))
    for k, nb in enumerate(near):
        others = [j for j in nb if deep.ids[j] != stars.ids[k]]
        out[k] = bool(others) and bool(np.any(deep.vmag[others] <= stars.vmag[k] + dmag))
    return out
