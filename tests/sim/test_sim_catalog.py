"""Star catalogs: known stars, magnitude conversion, proper motion, cache round trip."""

import math

import numpy as np
import pytest
from gyrostar import catalog as catmod
from gyrostar.catalog import hp_to_v, load_catalog, propagate
from gyrostar.errors import ConfigError


@pytest.fixture(autouse=True)
def _cache(tmp_path_factory, monkeypatch):
    monkeypatch.setenv("GYROSTAR_CACHE", str(tmp_path_factory.getbasetemp() / "cache"))


def _star(cat, hip):
    i = int(np.flatnonzero(cat.ids == hip)[0])
    return cat.vectors[i], cat.vmag[i]


def test_hip2_known_stars_and_sorting():
    cat = load_catalog("hip2", 6.0, 2000.0)
    assert np.all(np.diff(cat.vmag) >= 0)
    assert cat.vectors.dtype == np.float64 and cat.ids.dtype == np.int64
    assert np.allclose(np.linalg.norm(cat.vectors, axis=1), 1.0)
    # Vega (HIP 91262): RA 279.2347°, Dec +38.7837° (J2000, ICRS), V = 0.03
    v, m = _star(cat, 91262)
    ra, dec = math.radians(279.23473479), math.radians(38.78368896)
    truth = np.array([math.cos(dec) * math.cos(ra), math.cos(dec) * math.sin(ra), math.sin(dec)])
    assert math.degrees(math.acos(min(1.0, v @ truth))) * 3600 < 0.1
    assert m == pytest.approx(0.03, abs=0.08)  # Hp(Vega) = 0.087: the colour transform leaves ~0.06
    # Polaris (HIP 11767) V = 1.98; number of stars V <= 6 on the sky is ~5,000
    assert _star(cat, 11767)[1] == pytest.approx(1.98, abs=0.05)
    assert 4500 < len(cat) < 5500


def test_barnards_star_proper_motion():
    # HIP 87937 moves 10.39"/yr: 25 years apart the vectors differ by ~260"
    a = load_catalog("hip2", 10.0, 2000.0)
    b = load_catalog("hip2", 10.0, 2025.0)
    va, _ = _star(a, 87937)
    vb, _ = _star(b, 87937)
    sep = math.degrees(math.acos(va @ vb)) * 3600
    assert sep == pytest.approx(10.39 * 25, rel=0.01)


def test_hp_to_v_bessell_points():
    # Bessell 2000 Table 2 rows (B-V, V-Hp): (0.0, -0.011)->~0, (0.465, -0.108), (0.878, -0.155)
    assert hp_to_v(np.array([5.0]), np.array([0.465]))[0] - 5.0 == pytest.approx(-0.108, abs=0.01)
    assert hp_to_v(np.array([5.0]), np.array([0.878]))[0] - 5.0 == pytest.approx(-0.155, abs=0.01)
    assert np.isfinite(hp_to_v(np.array([5.0]), np.array([np.nan]))[0])


def test_propagate_zero_motion_is_identity():
    ra, dec = np.array([0.3, 2.0]), np.array([-0.4, 1.2])
    v = propagate(ra, dec, np.zeros(2), np.zeros(2), 30.0)
    assert np.allclose(v[:, 2], np.sin(dec))


def test_cache_round_trip_identical(tmp_path, monkeypatch):
    monkeypatch.setenv("GYROSTAR_CACHE", str(tmp_path))
    a = load_catalog("hip2", 5.0, 2025.0)
    assert catmod.cache_path("hip2", 5.0, 2025.0).exists()
    b = load_catalog("hip2", 5.0, 2025.0)
    assert np.array_equal(a.ids, b.ids) and np.array_equal(a.vectors, b.vectors)
    assert np.array_equal(a.vmag, b.vmag) and a.epoch == b.epoch == 2025.0
    assert np.array_equal(a.b_v, b.b_v, equal_nan=True)


def test_tycho_vt_from_colour():
    cat = load_catalog("hip2", 6.0, 2000.0)
    # Polaris B-V = 0.64 (hip2): V_T = V + 0.090/0.850 * 0.64
    i = int(np.flatnonzero(cat.ids == 11767)[0])
    assert cat.b_v[i] == pytest.approx(0.64, abs=0.03)
    assert cat.tycho_vt()[i] - cat.vmag[i] == pytest.approx(0.090 / 0.850 * cat.b_v[i], abs=1e-9)
    assert np.isfinite(cat.b_v).mean() > 0.99


def test_gaia_agrees_with_hip2_for_bright_stars():
    g = load_catalog("gaia", 6.0, 2025.0)
    h = load_catalog("hip2", 6.0, 2025.0)
    assert abs(len(g) - len(h)) / len(h) < 0.05
    # every hip2 star V<5.5 has a gaia star within 1" with V within 0.1
    hb = h.brighter_than(5.5)
    dots = hb.vectors @ g.vectors.T
    best = dots.argmax(axis=1)
    sep = np.degrees(np.arccos(np.clip(dots[np.arange(len(hb)), best], -1, 1))) * 3600
    assert np.median(sep) < 0.5
    assert np.median(np.abs(g.vmag[best] - hb.vmag)) < 0.05


def test_bad_arguments():
    with pytest.raises(ConfigError):
        load_catalog("tycho")
    with pytest.raises(ConfigError):
        load_catalog("gaia", 11.0)
    with pytest.raises(ConfigError):
        load_catalog("hip2", float("nan"))
