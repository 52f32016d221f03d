"""Blended stars (:mod:`gyrostar.starid.blends`): the rule on hand-placed stars, and the real
pairs it names in the Hipparcos catalog."""

import numpy as np
from gyrostar.starid.blends import BLEND_DMAG, BLEND_PX, blended


def test_blended_stars_are_named_by_their_neighbours():
    """Within a 5 px radius, a star with a neighbour at most 3 mag fainter is a blend (its spot
    is not at its catalog place); a neighbour 4 mag fainter, one 6 px away, or the star's own
    entry in the deeper catalog do not make it one. Hand-placed stars at 30″ per px."""
    from types import SimpleNamespace

    px = np.radians(30.0 / 3600.0)
    def vec(x_px, y_px):
        v = np.array([x_px * px, y_px * px, 1.0])
        return v / np.linalg.norm(v)

    # id: (x px, y px, V); 1-2 a pair 3 px apart 0.5 mag apart; 3 with a V+4 star 2 px away;
    # 5 with a V+1 star 6 px away; 7 alone (its own entry only)
    stars = {1: (0, 0, 5.0), 2: (3, 0, 5.5), 3: (100, 0, 5.0), 4: (100, 2, 9.0), 5: (200, 0, 5.0),
             6: (206, 0, 6.0), 7: (300, 0, 4.0)}
    def catalog(ids):
        return SimpleNamespace(ids=np.array(ids), vectors=np.array([vec(*stars[i][:2]) for i in ids]),
                               vmag=np.array([stars[i][2] for i in ids]))
    cat = catalog([1, 2, 3, 5, 6, 7])
    deep = catalog([1, 2, 3, 4, 5, 6, 7])
    got = blended(cat, deep, 5.0 * px, BLEND_DMAG)
    assert got.tolist() == [True, True, False, False, False, False]


def test_hipparcos_pairs_on_the_demo_camera():
    """At the loop's radius (``BLEND_PX``): HIP 24020 / 24019 (V 5.90 / 5.94, 0.4 px apart at
    the demo camera's 30.9″/px: the index keeps the first, the second is the pruned member) and
    HIP 81292 / 81290 (2.9 px, both indexed) are blends; HIP 12086 (V 5.40, a V 6.74 star 4.6 px
    away) and Vega (HIP 91262) are not."""
    from gyrostar.camera import camera_preset
    from gyrostar.catalog import load_catalog
    from gyrostar.starid.index import load_index

    cam = camera_preset("xing2012")
    idx = load_index("hip2", 6.5, max_sep_deg=12.2)
    deep = load_catalog("hip2", 6.5 + BLEND_DMAG)
    got = blended(idx, deep, BLEND_PX / cam.focal_length_px, BLEND_DMAG)
    row = {int(h): k for k, h in enumerate(idx.ids)}
    pos = {int(h): k for k, h in enumerate(deep.ids)}
    for a, b, sep_px in ((24020, 24019, 0.4), (81292, 81290, 2.9), (12086, 12091, 4.6)):
        sep = np.arccos(deep.vectors[pos[a]] @ deep.vectors[pos[b]]) * cam.focal_length_px      # px
        assert abs(sep - sep_px) < 0.1, (a, b, sep)
        assert got[row[a]] == (sep_px < BLEND_PX)
    assert 24019 not in row and got[row[81290]]
    assert not got[row[91262]]
    assert 0.002 < got.mean() < 0.05          # a per cent or so of the index
