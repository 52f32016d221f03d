"""The orbit environment on the sensor: stray light, the Earth, the Moon, temperature, and the
renderers' invariants with it (window pixels = frame pixels; off = exactly as before)."""

import math

import numpy as np
import pytest
from env_helpers import away_from, pointing, scenario
from gyrostar.attitude import quat_to_dcm
from gyrostar.catalog import load_catalog
from gyrostar.mocks.environment import Environment, pst
from gyrostar.mocks.sky import Sky
from sim_helpers import one_star_catalog

ADC_MAX = 1023          # xing2012: 10-bit
GAIN = 5.0              # xing2012: e-/ADU


@pytest.fixture(scope="module")
def catalog():
    return load_catalog("hip2", 7.0)


def _centre_electrons(sky, q, t_s, ref, half=4):
    """Mean electrons a patch at the sensor's centre holds over a render without the environment."""
    img, _ = sky.render_frame(q, np.zeros(3), frame=1, noise=False, t_s=t_s)
    img0, _ = ref.render_frame(q, np.zeros(3), frame=1, noise=False)
    c = sky.camera.width_px // 2
    patch = (slice(c - half, c + half), slice(c - half, c + half))
    return float(np.mean(img[patch].astype(float) - img0[patch].astype(float)) * GAIN), img


def test_pst_curve_shape():
    env = Environment(scenario("orbit", "stray_light"), seed=1, horizon_s=60.0)
    sky = Sky(one_star_catalog([0, 0, 1.0]), "xing2012", environment=env)
    q = pointing([1.0, 0.0, 0.0])
    p = env.exposure(0.0, q, 0, sky.preset, sky.params).params
    half = math.atan(math.hypot(1024, 1024) / 2 / sky.camera.focal_length_px)
    # at the field's edge the lit lens: pst_edge; far beyond the cut-off the vanes: 1e-9·(30/θ)²
    assert pst(half, p) == pytest.approx(1e-3, rel=1e-6)
    for deg in (40.0, 60.0, 120.0):
        assert pst(math.radians(deg), p) == pytest.approx(1e-9 * (30.0 / deg) ** 2, rel=1e-6)
    # it falls monotonically through the exclusion angle, by more than 3 decades within ±2°
    th = np.radians(np.linspace(10.0, 60.0, 501))
    vals = np.array([pst(x, p) for x in th])
    assert np.all(np.diff(vals) < 0)
    assert pst(math.radians(28.0), p) / pst(math.radians(32.0), p) > 1e3


def test_sun_background_rises_towards_the_exclusion_angle_and_blinds_inside(catalog):
    scen = scenario("orbit", "stray_light")
    env = Environment(scen, seed=2, horizon_s=60.0)
    sky = Sky(catalog, "xing2012", seed=2, environment=env)
    ref = Sky(catalog, "xing2012", seed=2)
    geo = env.geometry(0.0)
    assert not geo["eclipse"]
    zen = -geo["nadir"]
    det, cam = sky.preset.detector, sky.camera
    # electrons per pixel per unit PST from the Sun (V = -26.74 at 1 AU), by hand
    k_sun = (1e10 * 10 ** (0.4 * 26.74) * (1.495978707e8 / geo["sun_km"]) ** 2 * cam.pixel_pitch_m ** 2
             * det.qe * det.exposure_s)
    levels = []
    for ang in (45.0, 36.0, 32.0, 31.0, 30.5, 30.0, 29.5):
        q = pointing(away_from(geo["sun"], ang, zen))
        tr = env.truth(0.0 + det.exposure_s / 2, q, sky.preset, sky.params)
        assert tr["sun_angle_deg"] == pytest.approx(ang, abs=0.02)
        assert tr["earth_limb_angle_deg"] > 40.0
        p = env.exposure(0.0, q, 0, sky.preset, sky.params).params
        parts = tr["stray_parts_e_px"]
        assert parts["sun"] == pytest.approx(k_sun * pst(math.radians(ang), p), rel=1e-3)
        assert parts["moon"] < 1e-3 * parts["sun"]          # full Moon, opposite the Sun
        assert parts["earth"] < 0.2 * parts["sun"]          # the sunlit Earth, > 40° below
        assert tr["stray_e_px"] == pytest.approx(sum(parts.values()), rel=1e-12)
        levels.append(tr["stray_e_px"])
        if tr["stray_e_px"] > 20.0:      # well above the 5 e-/ADU rounding
            measured, _ = _centre_electrons(sky, q, 0.0, ref)
            assert measured == pytest.approx(tr["stray_e_px"], rel=0.15, abs=0.6)
    assert np.all(np.diff(levels) > 0)
    assert levels[0] < 0.5 and levels[-1] > 200.0
    # 27° from the Sun, inside the baffle's cut-off: the centre of the sensor is saturated
    q = pointing(away_from(geo["sun"], 27.0, zen))
    _, img = _centre_electrons(sky, q, 0.0, ref)
    assert np.all(img[500:524, 500:524] == ADC_MAX)
    # the side of the sensor towards the Sun is the brighter (the gradient's direction)
    q = pointing(away_from(geo["sun"], 31.0, zen))
    img, _ = sky.render_frame(q, np.zeros(3), frame=1, noise=False, t_s=0.0)
    s_cam = quat_to_dcm(q) @ geo["sun"]
    toward = np.array([s_cam[0], s_cam[1]]) / math.hypot(s_cam[0], s_cam[1])
    near = img[tuple(np.round(511.5 + 400 * toward[::-1]).astype(int))]
    far = img[tuple(np.round(511.5 - 400 * toward[::-1]).astype(int))]
    assert near > far + 5


def test_no_sun_stray_light_in_the_earth_shadow(catalog):
    scen = scenario("orbit", "stray_light", orbit={"phase_deg": 180.0})
    env = Environment(scen, seed=2, horizon_s=60.0)
    sky = Sky(catalog, "xing2012", seed=2, environment=env)
    geo = env.geometry(0.0)
    assert geo["eclipse"]
    q = pointing(away_from(geo["sun"], 31.0, -geo["nadir"]))
    tr = env.truth(0.005, q, sky.preset, sky.params)
    assert tr["eclipse"] and tr["sun_angle_deg"] < 32.0
    assert tr["stray_e_px"] < 0.01


def test_earth_hides_stars_and_its_sunlit_disk_saturates():
    scen = scenario("orbit", "stray_light")
    env = Environment(scen, seed=4, horizon_s=60.0)
    geo = env.geometry(0.0)
    # a star straight below (behind the Earth) and the boresight on the Earth's sunlit limb region
    cat = one_star_catalog(geo["nadir"], vmag=3.0)
    sky = Sky(cat, "xing2012", seed=4, environment=env)
    ref = Sky(cat, "xing2012", seed=4)
    q = pointing(geo["nadir"])
    img, truth = sky.render_frame(q, np.zeros(3), frame=3, noise=False, t_s=0.0)
    _, truth0 = ref.render_frame(q, np.zeros(3), frame=3, noise=False)
    assert truth0.electrons[0] > 1e4 and truth.electrons[0] == 0.0
    assert np.all(img == ADC_MAX)              # the day side fills the field
    # seen from the night side the Earth is dark: the star is hidden and nothing saturates
    night = Environment(scenario("orbit", "stray_light", orbit={"phase_deg": 180.0}), seed=4, horizon_s=60.0)
    g2 = night.geometry(0.0)
    sky2 = Sky(one_star_catalog(g2["nadir"], vmag=3.0), "xing2012", seed=4, environment=night)
    img2, truth2 = sky2.render_frame(pointing(g2["nadir"]), np.zeros(3), frame=3, noise=False, t_s=0.0)
    assert truth2.electrons[0] == 0.0
    assert np.median(img2) < 40 and img2.max() < ADC_MAX


def test_windows_equal_the_frame_with_every_hazard_on(catalog):
    scen = scenario("orbit", "stray_light", "moon", "radiation", "thermal",
                    orbit={"epoch_utc": "2026-03-28T12:00:00", "phase_deg": 180.0},
                    radiation={"flux_cm2_s": 2000.0, "hot_pixels_per_hour": 36000.0},
                    thermal={"temperature_c": 31.0})
    env = Environment(scen, seed=9, horizon_s=60.0)
    sky = Sky(catalog, "xing2012", seed=9, environment=env)
    geo = env.geometry(10.0)
    q = pointing(away_from(geo["moon"], 1.5, [0, 0, 1.0]))
    omega = np.radians([0.3, -0.2, 0.1])
    img, truth = sky.render_frame(q, omega, frame=7, t_s=10.0)
    hits, _ = env.hits(7, 10.0, sky.preset)
    assert len(hits) > 5
    rows = np.arange(0, 1024, 3)
    spans = np.array([[i, r, 0, 1024] for i, r in enumerate(rows)], np.int32)
    px = sky.window_pixels(spans, q, omega, frame=7, t_s=10.0)
    assert np.array_equal(px, img[rows].ravel())
    px2, truth2 = sky.render_windows(spans, q, omega, frame=7, t_s=10.0)
    assert np.array_equal(px2, px) and np.array_equal(truth2.uv, truth.uv)


def test_off_by_default_and_without_a_time(catalog):
    scen = scenario()
    assert scen.hazards == [] and Environment.from_scenario(scen, 1) is None
    env = Environment(scenario("orbit", "stray_light", "radiation"), seed=3, horizon_s=60.0)
    plain = Sky(catalog, "xing2012", seed=3)
    with_env = Sky(catalog, "xing2012", seed=3, environment=env)
    q = pointing([0.3, 0.5, 0.8])
    spans = np.array([[0, r, 400, 460] for r in range(480, 540)], np.int32)
    # an environment is used only with a scenario time: without one the pixels are the plain sky's
    a, _ = plain.render_frame(q, np.zeros(3), frame=2)
    b, _ = with_env.render_frame(q, np.zeros(3), frame=2)
    assert np.array_equal(a, b)
    assert np.array_equal(plain.window_pixels(spans, q, frame=2), with_env.window_pixels(spans, q, frame=2))
    assert np.array_equal(plain.window_pixels(spans, q, frame=2, t_s=5.0), a[480:540, 400:460].ravel())


def test_dark_current_doubles_every_7_degrees_and_focal_length_drifts(catalog):
    det_dark_e = 500.0 * 0.010              # xing2012: 500 e-/s at the reference 20 °C, 10 ms
    ref = Sky(catalog, "xing2012", seed=6)
    q = pointing([0.2, -0.4, 0.9])
    img0, truth0 = ref.render_frame(q, np.zeros(3), frame=1)
    for temp, factor in ((27.0, 2.0), (34.0, 4.0), (13.0, 0.5)):
        env = Environment(scenario("thermal", thermal={"temperature_c": temp, "focal_ppm_per_c": 50.0}),
                          seed=6, horizon_s=60.0)
        assert env.dark_factor(0.0) == pytest.approx(factor)
        sky = Sky(catalog, "xing2012", seed=6, environment=env)
        img, truth = sky.render_frame(q, np.zeros(3), frame=1, t_s=0.0)
        # mean dark signal (with the 1e-4 hot pixels at 100x) changes by (factor - 1) of itself; the
        # noise (the same draws in both frames) dithers the ADC's rounding
        mean_dark = det_dark_e * (1 - 1e-4) + 1e-4 * 50000.0 * 0.010
        diff = np.mean(img.astype(float) - img0.astype(float)) * GAIN
        assert diff == pytest.approx((factor - 1.0) * mean_dark, abs=0.1)
        # star positions scale about the principal point by 1 + 50 ppm/°C · ΔT
        c = np.array([511.5, 511.5])
        both = np.intersect1d(truth.ids[truth.in_field], truth0.ids[truth0.in_field])
        assert len(both) > 5
        uv = truth.uv[np.searchsorted(truth.ids, both)] if np.all(np.diff(truth.ids) > 0) else \
            np.array([truth.uv[truth.ids == i][0] for i in both])
        uv0 = np.array([truth0.uv[truth0.ids == i][0] for i in both])
        scale = np.linalg.norm(uv - c, axis=1) / np.linalg.norm(uv0 - c, axis=1)
        assert np.allclose(scale, 1.0 + 50e-6 * (temp - 20.0), rtol=0, atol=1e-9)


def test_thermal_swing_follows_the_orbit():
    env = Environment(scenario("orbit", "thermal", thermal={"temperature_c": 10.0, "swing_c": 8.0}), seed=1,
                      horizon_s=60.0)
    p = env.orbit.period_s
    assert env.temperature_c(0.0) == pytest.approx(10.0)
    assert env.temperature_c(p / 4) == pytest.approx(18.0)
    assert env.temperature_c(3 * p / 4) == pytest.approx(2.0)
