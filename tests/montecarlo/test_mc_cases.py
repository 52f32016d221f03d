"""Monte Carlo cases: drawn from the seed alone, within the stated ranges, valid scenarios;
pooled percentiles and the results hash against independent computations."""

import math

import numpy as np
import pytest
from gyrostar.errors import ConfigError
from gyrostar.hil import config as hc
from gyrostar.hil.eval_loop import run_seeds
from gyrostar.hil.montecarlo import cases as C
from gyrostar.hil.montecarlo.campaign import results_sha256, summarize
from gyrostar.hil.montecarlo.metrics import ERR_EDGES_ARCSEC, empty_metrics, hist_percentiles


def test_case_depends_on_its_seed_only():
    a = C.draw_case(100_017, 30.0)
    # other draws in between (another worker's runs) change nothing
    for s in range(50):
        C.draw_case(s, 30.0)
    assert C.draw_case(100_017, 30.0) == a
    assert C.draw_case(100_018, 30.0) != a
    assert run_seeds(3, 4) == [300_000, 300_001, 300_002, 300_003]


def test_draws_stay_in_their_stated_ranges():
    prof = []
    for s in range(400):
        c = C.draw_case(s, 30.0)
        prof.append(c.profile)
        scen = C.case_scenario(c, 30.0)
        assert math.isclose(sum(seg.seconds for seg in scen.segments), 30.0, abs_tol=1e-9) or c.profile in (
            "slew", "tumble")
        assert sum(seg.seconds for seg in scen.segments) >= 30.0 - 1e-9
        assert -90 <= c.dec_deg <= 90 and 0 <= c.ra_deg < 360
        lo, hi = C.ARW_RANGE_DPS_RTHZ
        assert lo <= c.gyro_overrides["noise_density_dps_rthz"] <= hi
        if c.profile == "slew":
            assert 0.5 <= c.peak_rate_dps <= C.MAX_SLEW_DPS
            rates = [np.linalg.norm(seg.rate_dps) for seg in scen.segments]
            assert max(rates) == pytest.approx(c.peak_rate_dps)
        if c.profile == "tumble":
            assert C.TUMBLE_DPS[0] <= c.peak_rate_dps <= C.TUMBLE_DPS[1]
        if c.profile == "starless":
            (a, b), = c.eclipse
            assert 0 < a < b < 30.0
        assert len(c.false_spots) <= C.FALSE_SPOTS_MAX
        for u, v, m in c.false_spots:
            assert 0 <= u < 1024 and 0 <= v < 1024 and C.FALSE_SPOT_VMAG[0] <= m <= C.FALSE_SPOT_VMAG[1]
        assert all(f.kind == "link-corruption" and 0 < f.at_s < 30.0 for f in scen.faults)
    # every profile drawn at about its probability (400 draws: ±4.5σ)
    for p, want in zip(C.PROFILES, C.PROFILE_P):
        n = prof.count(p)
        assert abs(n - 400 * want) < 4.5 * math.sqrt(400 * want * (1 - want))


def test_pointing_is_uniform_on_the_sphere():
    dec = np.array([C.draw_case(s, 30.0).dec_deg for s in range(2000)])
    # uniform on the sphere: sin(dec) uniform on [-1, 1], mean 0, variance 1/3
    s = np.sin(np.radians(dec))
    assert abs(s.mean()) < 4.5 * math.sqrt(1 / 3 / 2000)
    assert abs(np.mean(s * s) - 1 / 3) < 0.03


def test_case_runs_by_name_and_bad_names_are_config_errors():
    scen = hc.load_scenario("mc:100005@30")
    assert scen.name == "mc-100005" and scen.duration_s == 30.0
    assert scen == C.case_scenario(C.draw_case(100005, 30.0), 30.0)
    with pytest.raises(ConfigError, match="mc:SEED@DURATION"):
        hc.load_scenario("mc:12")
    with pytest.raises(ConfigError):
        hc.load_scenario("mc:x@30")


def test_pooled_percentiles_match_numpy_on_all_samples():
    rng = np.random.default_rng(0)
    runs = [rng.lognormal(1.0, 0.6, size=n) for n in (3000, 500, 8000)]
    hist = sum(np.histogram(r, ERR_EDGES_ARCSEC)[0] for r in runs)
    got = hist_percentiles(hist, (50, 95, 99))
    allv = np.concatenate(runs)
    for q in (50, 95, 99):
        # the grid is 0.5 % per bin: the pooled value is the bin's upper edge
        assert got[f"p{q}"] == pytest.approx(np.percentile(allv, q), rel=0.012)


def _row(seed, **kw):
    r = {"seed": seed, "profile": "rest", "peak_rate_dps": 0.0, "failed": False, "reason": "", **empty_metrics(),
         "frames": 10, "overruns": 0, "samples_lost": 0, "wall_s": 1.0, "mid_exposure_error_arcsec": 0.4}
    r.update(kw)
    return r


def test_results_hash_ignores_order_and_wall_time_but_not_values():
    rows = [_row(1, ttff_s=0.5), _row(2, ttff_s=0.7)]
    h = results_sha256(rows)
    assert results_sha256(list(reversed(rows))) == h
    assert results_sha256([_row(1, ttff_s=0.5, wall_s=9.0), _row(2, ttff_s=0.7)]) == h
    assert results_sha256([_row(1, ttff_s=0.5 + 1e-15), _row(2, ttff_s=0.7)]) != h


def test_summary_counts_failures_and_wrong_runs():
    rows = [_row(1, ttff_s=0.5), _row(2, failed=True, reason="DeviceError: x"), _row(3, wrong_attitude=True)]
    s = summarize(rows)
    assert s["runs"] == 3 and s["failed"] == 1 and s["wrong_attitude_runs"] == 1
    assert s["failures"] == [{"seed": 2, "reason": "DeviceError: x"}]
