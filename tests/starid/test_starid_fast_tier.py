"""Pyramid's thinned first tier on sparse fields: a field of no more spots than the tier
takes gets max(fast_triangles, C(n,3)/2) triangles there, then the full index. Fields:
the paper-001 camera (qian2015) on the real Hipparcos catalog, truth = their own star ids."""

from math import comb

import numpy as np
import pytest
from gyrostar.attitude import random_attitudes
from gyrostar.errors import ConfigError
from gyrostar.hil.evaluation import eval_starid as E
from gyrostar.mocks.star_lists import score
from gyrostar.starid.pyramid import Pyramid


@pytest.fixture(scope="module")
def qian():
    cfg = E.TrialConfig(method="pyramid", preset="qian2015")
    return cfg, E.setup(cfg)


def _variant(pyr, **kw):
    return Pyramid(pyr.index, pyr.camera, sigma_px=pyr.sigma_px, sigma_mag=pyr.sigma_mag, faint=pyr.faint, **kw)


def test_sparse_field_leaves_the_thinned_tier_after_its_share_of_triangles(qian):
    cfg, s = qian
    cam, sky, pyr = s["camera"], s["sky"], s["ident"]
    assert pyr.fast_index is not None and pyr.fast_triangles == 10 and pyr.fast_spots == 10
    thin_only = Pyramid(pyr.fast_index, cam, sigma_px=pyr.sigma_px, sigma_mag=pyr.sigma_mag, faint=pyr.faint)
    full_only = _variant(pyr)
    uncapped = _variant(pyr, fast_index=pyr.fast_index, fast_triangles=10**6)
    rng = np.random.default_rng(4)
    shown = 0
    for q in random_attitudes(1500, rng):
        f = sky.observe(cam, q, cfg.mag_limit, cfg.total_pos_noise, cfg.total_mag_noise, 0, rng)
        n = len(f.uv)
        a, u = pyr.identify(f.uv, mag=f.mag), uncapped.identify(f.uv, mag=f.mag)
        for r in (a, u):
            assert score(r.ids, f.truth, f.alt)[1] == 0, "a wrong identification was output"
        if not 3 <= n <= pyr.fast_spots:
            assert a.triangles == u.triangles and np.array_equal(a.ids, u.ids)   # the cap is for sparse fields
            continue
        t, k = thin_only.identify(f.uv, mag=f.mag), full_only.identify(f.uv, mag=f.mag)
        if t.ok or not (k.ok and u.ok and u.triangles == t.triangles + k.triangles):
            continue
        # the thinned tier lacks this field's stars: T of its triangles tried in vain, then k in the full tier
        cap = max(10, comb(n, 3) // 2)
        assert a.triangles == min(t.triangles, cap) + k.triangles
        assert a.ok and np.array_equal(a.ids, k.ids) and np.array_equal(a.ids, u.ids)
        shown += t.triangles > cap
    assert shown >= 5, f"only {shown} sparse fields where the thinned tier ran out of its share"


def test_fast_triangles_must_be_positive(qian):
    _, s = qian
    with pytest.raises(ConfigError):
        _variant(s["ident"], fast_index=s["ident"].fast_index, fast_triangles=0)
