"""The circular orbit, the Sun, the Moon and the Earth's shadow against hand-computed truth."""

import math

import numpy as np
import pytest
from gyrostar.hil import config as hc
from gyrostar.mocks.orbit import R_EARTH_KM, CircularOrbit, epoch_jd


def _orbit(**kw):
    cfg = hc.OrbitConfig(enabled=True, **kw)
    cfg.validate()
    return CircularOrbit(cfg, horizon_s=120.0)


def _sun_almanac(jd):
    """Low-precision solar RA/Dec (deg) of the Astronomical Almanac (good to 0.01° 1950–2050), its
    ecliptic longitude carried from the equinox of date back to J2000 (general precession
    5029.1″ a century) to compare with the GCRS (J2000-aligned) axes."""
    n = jd - 2451545.0
    L = math.radians(280.460 + 0.9856474 * n - 5029.1 / 3600.0 * n / 36525.0)
    g = math.radians(357.528 + 0.9856003 * n)
    lam = L + math.radians(1.915) * math.sin(g) + math.radians(0.020) * math.sin(2 * g)
    eps = math.radians(23.4393)        # the J2000 obliquity
    ra = math.degrees(math.atan2(math.cos(eps) * math.sin(lam), math.cos(lam))) % 360.0
    return ra, math.degrees(math.asin(math.sin(eps) * math.sin(lam)))


def test_period_and_radius_of_a_500_km_orbit():
    o = _orbit()
    # Kepler: T = 2π √(a³/μ), a = 6878.137 km → 94.6 min
    assert o.period_s == pytest.approx(2 * math.pi * math.sqrt(6878.137 ** 3 / 398600.4418), rel=1e-12)
    assert 5670 < o.period_s < 5685
    for t in (0.0, 100.0, 1234.5):
        assert np.linalg.norm(o.position_km(t)) == pytest.approx(R_EARTH_KM + 500.0, rel=1e-12)
    # a quarter period on from the node the spacecraft is at its highest latitude, = the inclination
    # (retrograde orbit: 180° − i)
    assert o.subpoint_deg(o.period_s / 4)[0] == pytest.approx(180.0 - 97.4, abs=1e-6)


@pytest.mark.parametrize("epoch", ["2026-03-20T12:00:00", "2026-06-21T03:30:00", "2031-11-02T18:00:00"])
def test_sun_direction_matches_the_almanac(epoch):
    o = _orbit(epoch_utc=epoch)
    s = o.sun_km(0.0)
    ra = math.degrees(math.atan2(s[1], s[0])) % 360.0
    dec = math.degrees(math.asin(s[2] / np.linalg.norm(s)))
    ra0, dec0 = _sun_almanac(epoch_jd(epoch))
    assert abs((ra - ra0 + 180) % 360 - 180) < 0.03 and abs(dec - dec0) < 0.03
    assert 0.98 < np.linalg.norm(s) / 1.495978707e8 < 1.02


def test_moon_distance_and_parallax():
    o = _orbit(epoch_utc="2026-03-28T12:00:00")
    for t in (0.0, 60.0, 90.0):       # 90 s: between the table's nodes
        m = o.moon_km(t)
        assert 356000 < np.linalg.norm(m) < 407000
        topo = m - o.position_km(t)
        par = math.degrees(math.acos(m @ topo / np.linalg.norm(m) / np.linalg.norm(topo)))
        assert par <= math.degrees(math.asin(np.linalg.norm(o.position_km(t)) / np.linalg.norm(m))) + 1e-9
    # the Moon moves ~0.55 °/h geocentrically: the 60 s table's interpolation is smooth
    a, b = o.moon_km(29.0), o.moon_km(31.0)
    assert 0.5 < np.linalg.norm(b - a) / 2.0 < 1.2          # km/s


def test_ltan_sets_the_node_and_the_shadow():
    # at the ascending node at 10:30 local time the spacecraft is over the day side; half an orbit
    # later (22:30 at the descending node) it is in the Earth's shadow
    o = _orbit(epoch_utc="2026-03-20T12:00:00", ltan_h=10.5)
    assert not o.in_shadow(0.0)
    assert o.in_shadow(o.period_s / 2)
    # the node's local time: the Sun's hour angle there is -1.5 h (±0.2 h for the equation of time)
    r, s = o.position_km(0.0), o.sun_km(0.0)
    ha = math.degrees(math.atan2(r[1], r[0]) - math.atan2(s[1], s[0])) / 15.0
    assert abs(((ha + 12) % 24 - 12) - (10.5 - 12.0)) < 1e-9
    # its longitude: 12:00 UTC at local mean time 10:30 → 22.5° W (+ the equation of time, 7.5 min)
    lat, lon = o.subpoint_deg(0.0)
    assert abs(lat) < 1e-9 and abs(lon - (-22.5)) < 3.0


def test_raan_overrides_ltan():
    o = _orbit(raan_deg=40.0, ltan_h=3.0)
    r = o.position_km(0.0)
    assert math.degrees(math.atan2(r[1], r[0])) == pytest.approx(40.0, abs=1e-9)
