"""Detector noise: sampler statistics and a dark flat field against the preset's figures."""

import math

import numpy as np
import pytest
from gyrostar.mocks import pixel_noise
from gyrostar.mocks.sim_preset import load_preset
from gyrostar.mocks.sky import Sky
from sim_helpers import IDENTITY_Q, one_star_catalog


def test_table_normal_moments_and_tails():
    table = pixel_noise.normal_table()
    rng = np.random.default_rng(0)
    bits = rng.integers(0, 2**32, 400_000, dtype=np.uint64)
    z = np.array([pixel_noise.table_normal(b, table) for b in bits[:200_000]])
    assert abs(z.mean()) < 0.01 and abs(z.std() - 1.0) < 0.01
    assert np.mean(np.abs(z) > 3.0) == pytest.approx(2.7e-3, rel=0.25)
    assert pixel_noise.ndtri(0.975) == pytest.approx(1.959963985, abs=1e-8)
    assert pixel_noise.ndtri(1e-6) == pytest.approx(-4.753424309, abs=1e-6)


@pytest.mark.parametrize("lam", [0.7, 5.6, 25.0, 300.0])
def test_poisson_mean_and_variance(lam):
    # through the whole chain: a flat signal, no read noise, gain 1/64 e-/ADU to see the electrons
    det = load_preset("xing2012").detector_array()
    det[pixel_noise.D_READ] = 0.0
    det[pixel_noise.D_SKY_E] = 0.0
    det[pixel_noise.D_GAIN] = 1.0
    det[pixel_noise.D_BIAS] = 0.0
    det[pixel_noise.D_ADCMAX] = 65535.0
    h, w = 200, 500
    sig = np.full((h, w), lam)
    one = np.ones((h, w), dtype=np.float32)
    zero = np.zeros((h, w), dtype=np.float32)
    lam_bg, exp_bg = pixel_noise.background_maps(one, zero, det)
    n = pixel_noise.digitise_frame(sig, one, zero, lam_bg, exp_bg, 5, 0, det, True,
                                   pixel_noise.normal_table(), np.ones(h, dtype=bool)).astype(float)
    assert n.mean() == pytest.approx(lam, rel=0.02, abs=0.01)
    assert n.var() == pytest.approx(lam, rel=0.05)


def test_dark_frame_statistics_match_preset():
    p = load_preset("xing2012")
    d = p.detector
    sky = Sky(one_star_catalog([0, 0, -1.0]), p, seed=3)  # the only star is behind the camera
    img, truth = sky.render_frame(IDENTITY_Q, np.zeros(3), frame=0)
    assert not truth.in_field.any()
    gain_fp, dark = sky.fixed_pattern
    assert np.std(gain_fp) == pytest.approx(d.prnu_frac, rel=0.05)
    hot = dark > 0.5 * d.hot_pixel_dark_e_s * d.exposure_s
    assert hot.mean() == pytest.approx(d.hot_pixel_frac, rel=0.3)
    cold = ~hot
    assert dark[cold].mean() == pytest.approx(d.dark_current_e_s * d.exposure_s, rel=0.02)
    assert dark[cold].std() / dark[cold].mean() == pytest.approx(d.dsnu_frac, rel=0.1)
    lam = p.sky_electrons_per_px() + d.dark_current_e_s * d.exposure_s
    x = img[cold].astype(float)
    assert x.mean() == pytest.approx(d.bias_adu + lam / d.gain_e_per_adu, abs=0.05)
    # variance in ADU: (shot + DSNU spread + read) / g^2 + 1/12 quantisation
    dsnu_var = (d.dsnu_frac * d.dark_current_e_s * d.exposure_s) ** 2
    expect = (lam + dsnu_var + d.read_noise_e**2) / d.gain_e_per_adu**2 + 1 / 12
    assert x.var() == pytest.approx(expect, rel=0.05)
    # hot pixels stand out; nothing saturates without stars
    assert img[hot].mean() > d.bias_adu + 0.5 * d.hot_pixel_dark_e_s * d.exposure_s / d.gain_e_per_adu
    assert img.max() < 1023


def test_saturation_clips_at_adc_full_scale():
    p = load_preset("xing2012")
    sky = Sky(one_star_catalog([0, 0, 1.0], vmag=0.0), p, seed=1)
    img, _ = sky.render_frame(IDENTITY_Q, np.zeros(3), noise=False)
    assert img.max() == 2**p.detector.adc_bits - 1
    assert math.isclose(img[511:513, 511:513].min(), 1023)
