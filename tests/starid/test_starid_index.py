"""Catalog index: pairs, neighbour tables, voxel cones, thinning and the cache file."""

import math

import numpy as np
import pytest
from gyrostar.catalog import StarCatalog
from gyrostar.errors import ConfigError
from gyrostar.starid import index as sidx


def _random_sky(n, seed=1):
    rng = np.random.default_rng(seed)
    v = rng.normal(size=(n, 3))
    v /= np.linalg.norm(v, axis=1)[:, None]
    mag = np.sort(rng.uniform(1.0, 7.0, n))
    return StarCatalog("test", np.arange(n, dtype=np.int64) + 1, v, mag, 2025.0)


def test_pairs_neighbours_and_cones_match_brute_force():
    cat = _random_sky(1500)
    ix = sidx.build_index(cat, 12.0, double_sep_deg=0.0)
    dots = np.clip(cat.vectors @ cat.vectors.T, -1, 1)
    ang = np.arccos(dots)
    iu = np.triu_indices(len(cat), 1)
    close = ang[iu] < math.radians(12.0)
    assert ix.n_pairs == int(close.sum())
    assert np.all(np.diff(ix.pair_theta) >= 0)
    np.testing.assert_allclose(ix.pair_theta, np.arccos(np.einsum("ij,ij->i", ix.vectors[ix.pair_a],
                                                                  ix.vectors[ix.pair_b]).clip(-1, 1)))
    for s in (0, 17, 900):
        want = np.flatnonzero((ang[s] < math.radians(12.0)) & (np.arange(len(cat)) != s))
        assert sorted(ix.neighbours(s)) == list(want)
    rng = np.random.default_rng(2)
    for _ in range(20):
        c = rng.normal(size=3)
        c /= np.linalg.norm(c)
        r = rng.uniform(0.01, 0.3)
        got = ix.cone(c, r, mag_max=5.0)
        want = np.flatnonzero((cat.vectors @ c >= math.cos(r)) & (cat.vmag <= 5.0))
        assert list(got) == list(want)


def test_thinning_spreads_navigation_stars_and_drops_doubles():
    cat = _random_sky(4000)
    vec = cat.vectors.copy()
    vec[5] = vec[3] + np.array([1e-5, 0, 0])  # a 2″ double: star 5 is fainter than 3
    vec[5] /= np.linalg.norm(vec[5])
    cat = StarCatalog("test", cat.ids, vec, cat.vmag, 2025.0)
    keep = sidx.select_navigation_stars(cat.vectors, 0, 0.0, math.radians(0.03))
    assert 3 in keep and 5 not in keep
    nav = sidx.select_navigation_stars(cat.vectors, 3, math.radians(5.0))
    chord = 2 * math.sin(math.radians(5.0) / 2)
    kept = np.zeros(len(cat), dtype=bool)
    kept[nav] = True
    for i in range(len(cat)):  # replay the rule: kept iff < 3 brighter kept stars within 5°
        near = np.linalg.norm(cat.vectors[:i] - cat.vectors[i], axis=1) < chord
        assert kept[i] == (np.count_nonzero(near & kept[:i]) < 3)
    assert len(nav) < len(cat) / 2


def test_load_index_writes_and_reads_the_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("GYROSTAR_CACHE", str(tmp_path))
    a = sidx.load_index("hip2", 4.0, 10.0, 0)
    files = list((tmp_path / "starid").glob("index_hip2_*.npz"))
    assert len(files) == 1
    b = sidx.load_index("hip2", 4.0, 10.0, 0)
    np.testing.assert_array_equal(a.pair_theta, b.pair_theta)
    np.testing.assert_array_equal(a.ids, b.ids)
    assert b.kv_m == a.kv_m and b.vox_g == a.vox_g
    files[0].write_bytes(b"garbage")
    c = sidx.load_index("hip2", 4.0, 10.0, 0)  # a corrupt cache is rebuilt
    assert c.n_pairs == a.n_pairs


def test_bad_parameters():
    with pytest.raises(ConfigError):
        sidx.build_index(_random_sky(100), 90.0)
    with pytest.raises(ConfigError):
        sidx.build_index(_random_sky(100), 5.0, per_field=-1)


def test_an_index_too_large_to_build_is_a_config_error_before_it_is_built():
    """A uniform sky of n stars has n²(1 − cos θ)/4 pairs within θ: 40 000 stars to 40°
    hold ~94 M pairs (~6 GB to build) — refused in one line, not an out-of-memory kill."""
    rng = np.random.default_rng(1)
    v = rng.normal(size=(40_000, 3))
    v /= np.linalg.norm(v, axis=1)[:, None]
    cat = StarCatalog("synthetic", np.arange(len(v)), v, np.linspace(1.0, 9.0, len(v)), 2025.0, None)
    with pytest.raises(ConfigError, match=r"~9\d M pairs"):
        sidx.build_index(cat, 40.0)


def test_stars_beyond_the_navigation_limit_label_but_form_no_pairs(tmp_path, monkeypatch):
    """``nav_mag_limit``: every star is in the voxel grid (it can label a spot), only the
    stars to the limit are navigation stars with pairs; the cached index keeps the limit."""
    cat = _random_sky(3000)
    ix = sidx.build_index(cat, 12.0, double_sep_deg=0.0, nav_mag_limit=5.0)
    assert len(ix) == len(cat)
    np.testing.assert_array_equal(ix.is_nav, cat.vmag <= 5.0)
    assert ix.nav_limit == cat.vmag[cat.vmag <= 5.0].max() and ix.mag_limit == float(cat.vmag[-1])
    bright = np.flatnonzero(cat.vmag <= 5.0)
    ang = np.arccos(np.clip(cat.vectors[bright] @ cat.vectors[bright].T, -1, 1))
    assert ix.n_pairs == int((ang[np.triu_indices(len(bright), 1)] < math.radians(12.0)).sum())
    assert np.all(ix.is_nav[ix.pair_a]) and np.all(ix.is_nav[ix.pair_b])
    c = cat.vectors[len(cat) - 1]               # the faintest star: in the cones, not a navigation star
    assert len(cat) - 1 in ix.cone(c, 1e-3)
    assert sidx.build_index(cat, 12.0, double_sep_deg=0.0).nav_limit == ix.mag_limit  # default: all navigate

    monkeypatch.setenv("GYROSTAR_CACHE", str(tmp_path))
    deep = sidx.load_index("hip2", 4.0, 10.0, 0, label_depth_mag=0.5)
    flat = sidx.load_index("hip2", 4.0, 10.0, 0)
    assert len(list((tmp_path / "starid").glob("index_hip2_*.npz"))) == 2
    assert deep.nav_limit == flat.nav_limit == flat.mag_limit <= 4.0 and 4.4 < deep.mag_limit <= 4.5
    np.testing.assert_array_equal(deep.ids[deep.is_nav], flat.ids)
    np.testing.assert_array_equal(deep.pair_theta, flat.pair_theta)
    again = sidx.load_index("hip2", 4.0, 10.0, 0, label_depth_mag=0.5)
    assert again.nav_limit == deep.nav_limit and np.array_equal(again.is_nav, deep.is_nav)
    with pytest.raises(ConfigError, match="label_depth_mag"):
        sidx.load_index("hip2", 4.0, 10.0, 0, label_depth_mag=-0.1)
