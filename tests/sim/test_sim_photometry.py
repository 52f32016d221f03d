"""Photometry: signal electrons of an Mv 5 star in xing2012 against a hand computation."""

import math

import numpy as np
import pytest
from gyrostar.mocks.sim_preset import load_preset
from gyrostar.mocks.sky import Sky
from sim_helpers import IDENTITY_Q, one_star_catalog


def test_mv5_xing2012_electrons_match_hand_computation():
    # Hand computation (notes, CRLB paragraph): V = 0 gives 1e10 photons/s/m^2 in V;
    # aperture D = 80 mm -> A = pi * 0.04^2 = 5.0265e-3 m^2; T = 0.85; t = 10 ms; QE = 0.5.
    photons = 1e10 * 10 ** (-0.4 * 5.0) * (math.pi * 0.04**2) * 0.85 * 0.010
    hand = photons * 0.5
    assert photons == pytest.approx(4272, rel=1e-3)  # "~4,300 photons"
    assert hand == pytest.approx(2136, rel=1e-3)     # "~2,100 e-"
    preset = load_preset("xing2012")
    assert abs(preset.star_electrons(5.0) - hand) / hand < 0.10
    # the renderer puts exactly that charge on the sensor (pixel-integrated PSF conserves it)
    sky = Sky(one_star_catalog([0.001, -0.002, 1.0], 5.0), preset, seed=1)
    exp = sky.expose(IDENTITY_Q, np.zeros(3))
    total = sky.signal_frame(exp).sum()
    print(f"Mv5 xing2012: hand {hand:.1f} e-, preset {preset.star_electrons(5.0):.1f} e-, rendered {total:.1f} e-")
    assert abs(total - hand) / hand < 0.10
    assert total == pytest.approx(preset.star_electrons(5.0), rel=1e-6)


def test_magnitude_scale_and_sky_background():
    p = load_preset("xing2012")
    assert p.star_electrons(0.0) / p.star_electrons(5.0) == pytest.approx(100.0)
    # sky 22 mag/arcsec^2 over a (30.9")^2 pixel: V = 22 - 2.5 log10(955) = 14.55 per pixel
    px = math.degrees(15e-6 / 0.1) * 3600
    v_px = 22.0 - 2.5 * math.log10(px * px)
    assert p.sky_electrons_per_px() == pytest.approx(p.star_electrons(v_px), rel=1e-9)
    assert 0.01 < p.sky_electrons_per_px() < 1.0


def test_qian2015_v75_is_detectable():
    # the reason for the preset's 20 ms exposure: SNR ~ 8 in a 3x3 aperture at V 7.5
    p = load_preset("qian2015")
    n = p.star_electrons(7.5)
    var_px = p.detector.read_noise_e**2 + p.detector.dark_current_e_s * p.detector.exposure_s
    snr = n / math.sqrt(n + 9 * var_px)
    assert 5.0 < snr < 10.0
