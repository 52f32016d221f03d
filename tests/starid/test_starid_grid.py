"""Grid patterns (rotation invariance, hand-made example) and the lost-in-space grid baseline."""

import math

import numpy as np
from gyrostar.attitude import quat_to_dcm, random_attitudes
from gyrostar.camera import camera_preset
from gyrostar.catalog import load_catalog
from gyrostar.mocks.star_lists import Sky, score
from gyrostar.starid.grid import GridIdentifier, GridParams, grid_pattern, load_grid_database
from gyrostar.starid.index import load_index


def _unit(x_deg, y_deg):
    v = np.array([math.tan(math.radians(x_deg)), math.tan(math.radians(y_deg)), 1.0])
    return v / np.linalg.norm(v)


def test_pattern_by_hand():
    # reference at the pole, neighbour 1° along +y (outside br 0.3°), a star at 0.1° (inside
    # br: in the pattern, not a neighbour) and one at (x=-0.5°, y=1.5°)
    vecs = np.array([_unit(0, 0), _unit(0, 1.0), _unit(0.1, 0), _unit(-0.5, 1.5), _unit(0, 9.0)])
    p = GridParams(g=40, cell_deg=0.2, br_deg=0.3)
    out = np.empty(8, dtype=np.int64)
    k, nb = grid_pattern(vecs, 0, p.br, p.pr, p.g, p.cell, out)
    assert nb == 1
    # rotated by -90°: (x, y) → (y, -x); grid origin at -4°, cell 0.2°
    def cell(x, y):
        return int(math.floor((-x + 4) / 0.2)) * 40 + int(math.floor((y + 4) / 0.2))
    want = sorted({cell(0, 1.0), cell(0.1, 0), cell(-0.5, 1.5)})
    assert list(out[:k]) == want  # the 9° star is outside pr = 4°


def test_pattern_is_invariant_to_attitude():
    rng = np.random.default_rng(4)
    vecs = rng.normal(size=(40, 3)) * 0.02 + np.array([0, 0, 1.0])
    vecs /= np.linalg.norm(vecs, axis=1)[:, None]
    p = GridParams()
    a = np.empty(64, dtype=np.int64)
    b = np.empty(64, dtype=np.int64)
    for q in random_attitudes(5, rng):
        rot = vecs @ quat_to_dcm(q).T
        ka, na = grid_pattern(vecs, 3, p.br, p.pr, p.g, p.cell, a)
        kb, nb = grid_pattern(rot, 3, p.br, p.pr, p.g, p.cell, b)
        assert na == nb and ka == kb and np.array_equal(a[:ka], b[:kb])


def test_lost_in_space_grid_identifies_rich_fields():
    cam = camera_preset("qian2015")
    ix = load_index("hip2", 7.5, 5.67, 0)
    db = load_grid_database(ix, GridParams())
    sky = Sky(load_catalog("hip2", 8.0))
    gid = GridIdentifier(ix, db, cam, sigma_px=0.3)
    rng = np.random.default_rng(8)
    rich = ok = 0
    for q in random_attitudes(60, rng):
        f = sky.observe(cam, q, 7.5, 0.2, 0.0, 0, rng)
        r = gid.identify(f.uv)
        c, w = score(r.ids, f.truth, f.alt)
        assert w == 0
        if len(f.uv) >= 10:
            rich += 1
            ok += c >= 2
    assert rich >= 20 and ok >= 0.8 * rich
