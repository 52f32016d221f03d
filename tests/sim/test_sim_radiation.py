"""Particle hits and appearing hot pixels against the simulator's own hit list and hand figures."""

import math

import numpy as np
import pytest
from env_helpers import pointing, scenario
from gyrostar.mocks.environment import Environment
from gyrostar.mocks.sim_preset import load_preset
from gyrostar.mocks.sky import Sky
from sim_helpers import one_star_catalog

PRESET = load_preset("xing2012")
AREA_CM2 = (1024 * 15e-4) ** 2          # 1024² pixels of 15 µm
GAIN = 5.0


def _env(**radiation):
    return Environment(scenario("radiation", radiation=radiation), seed=11, horizon_s=60.0)


def test_hit_count_is_poisson_with_the_flux_times_area_times_exposure():
    env = _env(flux_cm2_s=500.0)
    lam = 500.0 * AREA_CM2 * 0.010
    assert env.hit_rate_per_frame(0.0, PRESET) == pytest.approx(lam)
    counts = np.array([len(env.hits(k, 0.0, PRESET)[0]) for k in range(400)])
    assert abs(counts.mean() - lam) < 4 * math.sqrt(lam / 400)
    assert abs(counts.var() / lam - 1.0) < 0.25           # Poisson: variance = mean
    # the same frame always holds the same hits (counter-based), another frame others
    a, b = env.hits(17, 0.0, PRESET)[0], env.hits(17, 0.0, PRESET)[0]
    assert np.array_equal(a, b) and not np.array_equal(a, env.hits(18, 0.0, PRESET)[0])


def test_tracks_and_charge():
    env = _env(flux_cm2_s=5000.0)
    hits = np.concatenate([env.hits(k, 0.0, PRESET)[0] for k in range(60)])
    assert len(hits) > 2000
    length = np.hypot(hits[:, 2] - hits[:, 0], hits[:, 3] - hits[:, 1])
    # cos θ = √U: the projected length depth·tan θ / pitch (10 µm / 15 µm) has median
    # (2/3)·tan(acos(√0.5)) = 2/3 px; a few per cent run beyond 5 px (grazing)
    assert np.median(length) == pytest.approx(2.0 / 3.0, rel=0.08)
    assert 0.01 < np.mean(length > 5.0) < 0.08
    # Landau-like charge: most probable near 80 e-/µm · 10 µm · path factor, a long upper tail
    q = hits[:, 4]
    assert 700 < np.percentile(q, 25) < np.median(q) < 1600
    assert np.percentile(q, 99) > 3 * np.median(q)
    # random angles: the track directions cover every quadrant alike
    ang = np.arctan2(hits[:, 3] - hits[:, 1], hits[:, 2] - hits[:, 0])
    counts = np.histogram(ang, bins=4, range=(-math.pi, math.pi))[0]
    assert counts.min() > 0.8 * counts.mean()


def test_rendered_pixels_hold_each_listed_deposit():
    env = _env(flux_cm2_s=3000.0)
    cat = one_star_catalog([0.0, 0.0, 1.0])
    sky = Sky(cat, "xing2012", seed=11, environment=env)
    ref = Sky(cat, "xing2012", seed=11)
    q = pointing([1.0, 0.0, 0.0])
    img, _ = sky.render_frame(q, np.zeros(3), frame=5, noise=False, t_s=0.0)
    img0, _ = ref.render_frame(q, np.zeros(3), frame=5, noise=False)
    hits, dep = env.hits(5, 0.0, PRESET)
    assert len(hits) > 30
    expect = np.zeros((1024, 1024))
    for r, c, e in dep:
        if 0 <= r < 1024 and 0 <= c < 1024:
            expect[int(r), int(c)] += e
    gain, _ = sky.fixed_pattern
    diff = img.astype(float) - img0.astype(float)
    hit = expect > 0
    # every deposit in its pixel (through the pixel's PRNU gain, 5 e-/ADU, rounding, the ADC's top)
    want = np.minimum(expect * gain / GAIN, 1023 - img0)
    assert np.all(np.abs(diff[hit] - want[hit]) <= 1.0 + 0.001 * want[hit])
    assert np.all(diff[~hit] == 0)
    # the total charge of the frame's hits is what reached the pixels
    on = (dep[:, 0] >= 0) & (dep[:, 0] < 1024) & (dep[:, 1] >= 0) & (dep[:, 1] < 1024)
    assert expect.sum() == pytest.approx(dep[on, 2].sum())


def test_saa_raises_the_flux_inside_its_box():
    env = Environment(scenario("orbit", "radiation", orbit={"phase_deg": -51.5}), seed=11, horizon_s=60.0)
    lat0, _ = env.orbit.subpoint_deg(0.0)
    assert lat0 < -50.0 and not env.in_saa(0.0)
    assert env.hit_rate_per_frame(0.0, PRESET) == pytest.approx(2.0 * AREA_CM2 * 0.010)
    assert env.in_saa(20.0)
    assert env.hit_rate_per_frame(20.0, PRESET) == pytest.approx(300.0 * AREA_CM2 * 0.010)


def test_hot_pixels_appear_and_stay():
    env = _env(flux_cm2_s=0.0, hot_pixels_per_hour=3600.0)
    hot = env.hot_pixels(120.0, PRESET)
    # a Poisson process of 1 per second: ~120 by 120 s, in time order, each staying
    assert 80 < len(hot) < 160 and np.all(np.diff(hot[:, 0]) > 0)
    assert np.array_equal(env.hot_pixels(60.0, PRESET), hot[hot[:, 0] <= 60.0])
    cat = one_star_catalog([0.0, 0.0, 1.0])
    sky = Sky(cat, "xing2012", seed=11, environment=env)
    q = pointing([1.0, 0.0, 0.0])
    t_a, r, c, dark = hot[3]
    r, c = int(r), int(c)
    before, _ = sky.render_frame(q, np.zeros(3), frame=1, noise=False, t_s=t_a - 0.02)
    after, _ = sky.render_frame(q, np.zeros(3), frame=1, noise=False, t_s=t_a + 0.02)
    gain, _ = sky.fixed_pattern
    want = min(dark * 0.010 * gain[r, c] / GAIN, 1023 - float(before[r, c]))
    assert float(after[r, c]) - float(before[r, c]) == pytest.approx(want, abs=1.0)
