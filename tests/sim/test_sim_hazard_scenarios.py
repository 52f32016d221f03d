"""The deterministic hazard scenarios (``hil/scenarios``) hold the geometry they are named for,
checked against the simulator's truth along each scenario's true attitude, and render it."""

import math

import numpy as np
import pytest
from env_helpers import scenario_attitudes
from gyrostar.catalog import load_catalog
from gyrostar.hil import config as hc
from gyrostar.mocks.environment import Environment
from gyrostar.mocks.sim_preset import load_preset
from gyrostar.mocks.sky import Sky

PRESET = load_preset("xing2012")
PARAMS = PRESET.camera.as_array()
FULL_SCALE_E = 1023 * 5.0 - 20 * 5.0       # the ADC's top above its bias, e-


def _truth_along(name, times):
    scen = hc.load_scenario(name)
    env = Environment.from_scenario(scen, seed=3)
    qs = scenario_attitudes(scen, times)
    return scen, env, [env.truth(float(t), q, PRESET, PARAMS) for t, q in zip(times, qs)]


def test_sun_near_exclusion_background_rises_then_blinds_then_recovers():
    t = np.arange(0.0, 30.0, 0.5)
    scen, env, tr = _truth_along("sun-near-exclusion", t)
    sun = np.array([x["sun_angle_deg"] for x in tr])
    bg = np.array([x["stray_e_px"] for x in tr])
    assert sun[0] == pytest.approx(38.0, abs=0.05) and sun[-1] == pytest.approx(38.0, abs=0.1)
    hold = (t >= 15.0) & (t < 18.0)
    assert np.all(np.abs(sun[hold] - 28.5) < 0.1)           # inside the 30° exclusion
    assert np.all(bg[hold] > FULL_SCALE_E)                   # blinded at the centre
    assert np.all(bg[t < 4.0] < 1.0)                         # harmless at 38°
    approach = (t >= 5.0) & (t <= 15.0)
    assert np.all(np.diff(bg[approach]) > 0)                 # rising as the Sun nears the cut-off
    assert not any(x["eclipse"] for x in tr) and min(x["earth_limb_angle_deg"] for x in tr) > 55.0
    assert scen.stray_light.exclusion_deg == 30.0


def test_earth_limb_sweeps_into_the_exclusion_and_out():
    t = np.arange(0.0, 36.0, 0.5)
    scen, env, tr = _truth_along("earth-limb", t)
    limb = np.array([x["earth_limb_angle_deg"] for x in tr])
    bg = np.array([x["stray_e_px"] for x in tr])
    earth = np.array([x["stray_parts_e_px"]["earth"] for x in tr])
    assert limb[0] == pytest.approx(40.0, abs=0.05)
    hold = (t >= 19.0) & (t < 22.0)
    assert np.all(limb[hold] < 29.0) and np.all(limb[hold] > 26.5)
    assert np.all(bg[hold] > FULL_SCALE_E) and np.all(earth[hold] > 0.95 * bg[hold])   # the Earth's light
    assert limb[-1] > 38.0 and bg[-1] < 2.0
    assert min(x["sun_angle_deg"] for x in tr) > 60.0 and not any(x["eclipse"] for x in tr)


def test_moon_in_field_is_rendered_away_from_the_tracked_stars():
    t = np.array([0.0, 12.0, 16.0, 29.0])
    scen, env, tr = _truth_along("moon-in-field", t)
    assert tr[0]["moon_uv"] is None and tr[0]["moon_angle_deg"] > 7.0       # out of the field at the start
    cam = PRESET.camera
    for x in tr[2:]:
        u, v = x["moon_uv"]
        assert 0 < u < cam.width_px and 0 < v < cam.height_px
        assert x["moon_angle_deg"] == pytest.approx(2.0, abs=0.1)
        # the disk's radius: R_moon / distance, through the focal length (independent of the kernel)
        assert x["moon_radius_px"] == pytest.approx(cam.focal_length_px * math.tan(math.radians(x["moon_radius_deg"])),
                                                    rel=1e-9)
        assert 0.25 < x["moon_radius_deg"] < 0.29
    # no star the loop tracks (V ≤ 6.5) or its neighbours (≤ 6.8) within 0.9° of the Moon
    geo = env.geometry(16.0)
    cat = load_catalog("hip2", 6.8)
    sep = np.degrees(np.arccos(np.clip(cat.vectors @ geo["moon"], -1.0, 1.0)))
    assert sep.min() > 0.9
    # the rendered disk: saturated where lit, its extent the disk's, its area the phase's lit fraction
    q = scenario_attitudes(scen, [16.0])[0]
    sky = Sky(load_catalog("hip2", 7.0), PRESET, seed=3, environment=env)
    img, truth = sky.render_frame(q, np.zeros(3), frame=1, noise=False, t_s=16.0)
    x = tr[2]
    (u, v), rm = x["moon_uv"], x["moon_radius_px"]
    rr, cc = np.mgrid[0:cam.height_px, 0:cam.width_px]
    sat = img >= 1023
    near = np.hypot(cc - u, rr - v) < rm + 1.5
    assert np.all(near[sat & (np.hypot(cc - u, rr - v) < 3 * rm)])
    cos_alpha = -(geo["sun_from_moon"] @ geo["moon"])
    lit = math.pi * rm * rm * (1 + cos_alpha) / 2
    assert np.count_nonzero(sat & near) == pytest.approx(lit, rel=0.05)
    assert 0.7 < (1 + cos_alpha) / 2 < 0.85                  # waxing gibbous
    # every tracked-class star in the field keeps its light, and is ≥ 100 px from the disk's centre
    bright = truth.in_field & (truth.vmag <= 6.5) & (truth.ids >= 0)
    assert np.count_nonzero(bright) >= 8 and np.all(truth.electrons[bright] > 0)
    assert np.hypot(truth.uv[bright, 0] - u, truth.uv[bright, 1] - v).min() > 100.0


def test_saa_pass_enters_the_anomaly_mid_run():
    t = np.arange(0.0, 30.0, 0.5)
    scen, env, tr = _truth_along("saa-pass", t)
    inside = np.array([x["in_saa"] for x in tr])
    lat = np.array([x["lat_deg"] for x in tr])
    assert not inside[t < 14.0].any() and inside[t >= 15.5].all()
    assert lat[0] == pytest.approx(-50.9, abs=0.05) and np.all(np.diff(lat) > 0)
    area_cm2 = (1024 * 15e-4) ** 2
    rate = np.array([x["hits_per_frame"] for x in tr])
    assert np.allclose(rate[~inside], 2.0 * area_cm2 * 0.010) and np.allclose(rate[inside], 300.0 * area_cm2 * 0.010)
    assert min(x["earth_limb_angle_deg"] for x in tr) > 90.0
    # hot pixels appear during the run (a Poisson process of 360 an hour: P(none in 30 s) = 5 %; this seed: some)
    assert len(env.hot_pixels(30.0, PRESET)) >= 1


def test_max_error_over_floor_judges_the_run_against_its_own_floor():
    from gyrostar.hil.acceptance import evaluate, failures

    scen = hc.load_scenario("moon-in-field")
    base = {"track_fraction": 0.95, "attitude_error_arcsec_1sigma": 4.0, "mode_seconds": {"TRACK": 28.5}}
    ok = evaluate(scen, dict(base, measured_over_floor=1.1), scen.duration_s)
    bad = evaluate(scen, dict(base, measured_over_floor=1.3), scen.duration_s)
    never = evaluate(scen, dict(base, measured_over_floor=None), scen.duration_s)
    assert ok["checks"]["max_error_over_floor"]["pass"] and not failures(ok)
    assert failures(bad) == ["max_error_over_floor: 1.3 > 1.2 x floor"]
    assert not never["checks"]["max_error_over_floor"]["pass"]


def test_run_summary_lists_the_hazards_and_the_truth_along_the_run():
    from gyrostar.hil import flatsat
    from gyrostar.hil.environment_report import environment_summary, summary_line

    cfg = hc.load_flatsat()
    scen = hc.load_scenario("saa-pass")
    truth = flatsat.Truth(scen, flatsat.simulated_gyro(cfg, scen, 3), t_origin=100.0)
    env = flatsat.scenario_environment(scen, 3)
    s = environment_summary(env, truth, PRESET, PARAMS, scen.duration_s, 100.0)
    assert set(s["parameters"]) == {"orbit", "radiation"}
    assert s["parameters"]["radiation"]["saa_flux_cm2_s"] == 300.0
    assert s["truth"]["saa_seconds"] == 15.0 and s["truth"]["eclipse_seconds"] == 0.0
    assert s["truth"]["earth_limb_angle_deg"][0] > 90.0 and "temperature_c" not in s["truth"]
    line = summary_line({"environment": s})
    assert "radiation (" in line and "saa_flux_cm2_s 300" in line and "SAA 15 s" in line
    assert summary_line({}) is None
