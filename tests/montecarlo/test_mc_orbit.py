"""Orbit Monte Carlo (``gyrostar eval loop --orbit``, issue 50): each case meets the hazard it
is drawn for — checked against the orbit model's own geometry — depends on its seed alone,
and the per-run figures (availability, re-acquisition, covariance consistency) are computed
right on hand-made output records."""

import math

import numpy as np
import pytest
from gyrostar.hil import config as hc
from gyrostar.hil.montecarlo import orbit_cases as O
from gyrostar.hil.montecarlo.campaign import summarize
from gyrostar.hil.montecarlo.metrics import WRONG_NEES, empty_metrics, orbit_metrics
from gyrostar.loop import record as R
from gyrostar.mocks.orbit import CircularOrbit

SEEDS = range(500000, 500040)


def _bore(scen):
    ra, dec = math.radians(scen.ra_deg), math.radians(scen.dec_deg)
    return np.array([math.cos(dec) * math.cos(ra), math.cos(dec) * math.sin(ra), math.sin(dec)])


def _ang(a, b):
    return math.degrees(math.acos(max(-1.0, min(1.0, float(a @ b)))))


def test_each_case_meets_its_hazard_and_clears_the_others():
    seen = set()
    for seed in SEEDS:
        case = O.draw_orbit_case(seed, 30.0)
        scen = O.orbit_case_scenario(case, 30.0)
        assert scen.hazards == ["orbit", "stray_light", "moon", "radiation", "thermal"]
        o = CircularOrbit(scen.orbit, horizon_s=60.0)
        r = o.position_km(0.0)
        sun = (o.sun_km(0.0) - r) / np.linalg.norm(o.sun_km(0.0) - r)
        moon = (o.moon_km(0.0) - r) / np.linalg.norm(o.moon_km(0.0) - r)
        nadir = -r / np.linalg.norm(r)
        rho = math.degrees(o.earth_radius_angle())
        d = _bore(scen)
        excl = scen.stray_light.exclusion_deg
        sun_a, moon_a, limb = _ang(d, sun), _ang(d, moon), _ang(d, nadir) - rho
        seen.add(case.hazard)
        if case.hazard == "sun":
            assert sun_a == pytest.approx(excl + case.angle_deg, abs=0.01)
            assert not o.in_shadow(0.0)
        else:
            assert sun_a > excl + O.CLEAR_DEG
        if case.hazard == "moon":
            assert moon_a == pytest.approx(case.angle_deg, abs=0.01) and moon_a < 4.4
        else:
            assert moon_a > O.CLEAR_DEG
        if case.hazard == "earth":
            assert limb == pytest.approx(excl + case.angle_deg, abs=0.01)
        else:
            assert limb > excl + O.CLEAR_DEG
        if case.hazard == "saa":
            lat, lon = o.subpoint_deg(15.0)
            (a, b), (c, e) = scen.radiation.saa_lat_deg, scen.radiation.saa_lon_deg
            assert a <= lat <= b and c <= lon <= e, (lat, lon)
        assert O.TEMPERATURE_C[0] <= scen.thermal.temperature_c <= O.TEMPERATURE_C[1]
    assert seen == set(O.HAZARDS)


def test_orbit_case_depends_on_its_seed_only_and_runs_by_name():
    a = O.draw_orbit_case(500003, 30.0)
    assert O.draw_orbit_case(500003, 30.0) == a
    assert O.draw_orbit_case(500004, 30.0) != a
    scen = hc.load_scenario("mco:500003@30")
    assert scen.name == "mco-500003" and scen.ra_deg == a.loop.ra_deg and scen.orbit.epoch_utc == a.epoch_utc
    with pytest.raises(hc.ConfigError, match="mco:SEED@DURATION"):
        hc.load_scenario("mco:5x@30")


def _records(modes, valid, dt=0.0025, err_rad=0.0, sigma_rad=1e-5, reason=0):
    n = len(modes)
    out = R.empty(n)
    out["t"] = 100.0 + dt * np.arange(n)
    out["mode"] = modes
    out["flags"] = np.where(valid, R.FLAG_ATTITUDE_VALID, 0) | (np.asarray(reason) << R.REASON_SHIFT)
    half = 0.5 * np.asarray(err_rad, float) * np.ones(n)
    out["q"] = np.column_stack([np.sin(half), np.zeros(n), np.zeros(n), np.cos(half)])   # about body x
    out["cov"][:, 0, 0] = np.asarray(sigma_rad, float) ** 2
    out["cov"][:, 1, 1] = np.asarray(sigma_rad, float) ** 2
    truth = np.zeros(n, R.TRUTH_DTYPE)
    truth["t"] = out["t"]
    truth["q"] = [0.0, 0.0, 0.0, 1.0]
    return out, truth


def test_orbit_figures_on_hand_made_records():
    A, T, C = R.MODE_ACQUIRE, R.MODE_TRACK, R.MODE_COAST
    # 0.1 s acquiring, 1 s tracking, 0.5 s blinded coast, 0.25 s acquiring, 1 s tracking, 0.2 s coast to the end
    modes = [A] * 40 + [T] * 400 + [C] * 200 + [A] * 100 + [T] * 400 + [C] * 80
    valid = [m != A for m in modes]
    reason = [R.REASON_BLINDED if i in range(440, 740) else 0 for i in range(len(modes))]
    err = np.full(len(modes), 2e-5)                 # 2 σ: inside the covariance
    err[700] = 1e-3                                 # one ACQUIRE output far off: not valid, not counted
    err[1000] = 7e-5                                # 7 σ on a valid output: NEES 49 > 41.45
    out, truth = _records(modes, valid, err_rad=err, reason=reason)
    res = {"counters": {"spots_rejected_hit": 3, "frames_blinded": 50}, "frames": 200,
           "environment": {"truth": {"hits_per_frame": [0.1, 0.3], "saa_seconds": 2.0}}}
    m = orbit_metrics(out, truth, 100.0, res)
    assert m["availability"] == pytest.approx(1 - 140 / 1220)
    assert m["blinded_fraction"] == pytest.approx(300 / 1220)
    assert m["outages_s"] == [pytest.approx(300 * 0.0025)]
    assert m["unrecovered_s"] == pytest.approx(79 * 0.0025)
    assert m["valid_wrong_outputs"] == 1 and 7.0 ** 2 > WRONG_NEES > 6.0 ** 2
    assert m["valid_err_hist"].sum() == 1080
    assert m["hits_expected"] == pytest.approx(0.2 * 200) and m["spots_rejected_hit"] == 3
    row = {"seed": 1, "profile": "rest", "peak_rate_dps": 0.0, "failed": False, "reason": "", "hazard": "moon",
           **empty_metrics(), **m, "frames": 200, "overruns": 0, "samples_lost": 0, "mid_exposure_error_arcsec": 1.0}
    s = summarize([row, {**row, "seed": 2, "hazard": "sun"}])
    assert s["orbit"]["by_hazard"]["moon"]["reacquire_s"]["outages"] == 1
    assert s["orbit"]["all"]["valid_outside_covariance_outputs"] == 2
