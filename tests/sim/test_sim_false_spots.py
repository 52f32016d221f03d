"""Stray-light glints: sensor-fixed point sources rendered like stars, independent of attitude."""

import math

import numpy as np
from gyrostar.attitude import quat_from_boresight
from gyrostar.mocks.sky import Sky
from sim_helpers import IDENTITY_Q, one_star_catalog

SPOT = (300.4, 611.7, 4.5)


def _cog(img, u, v, half=6):
    r0, c0 = int(round(v)) - half, int(round(u)) - half
    patch = img[r0:r0 + 2 * half + 1, c0:c0 + 2 * half + 1].astype(float)
    patch -= np.median(img)
    patch[patch < 0] = 0
    rr, cc = np.mgrid[r0:r0 + 2 * half + 1, c0:c0 + 2 * half + 1]
    return (patch * cc).sum() / patch.sum(), (patch * rr).sum() / patch.sum(), patch.sum()


def test_glint_stays_on_the_sensor_while_the_star_moves():
    cat = one_star_catalog([0.0, 0.0, 1.0], vmag=4.5)
    sky = Sky(cat, "xing2012", seed=3, false_spots=[SPOT])
    ref = Sky(cat, "xing2012", seed=3)
    omega = np.radians([4.0, -3.0, 0.0])
    q1 = quat_from_boresight(math.radians(0.3), math.radians(0.2), 0.0)
    for q in (IDENTITY_Q, q1):
        img, truth = sky.render_frame(q, omega, frame=2, noise=False)
        img0, truth0 = ref.render_frame(q, omega, frame=2, noise=False)
        # the glint is listed after the stars, with id -1, at its sensor position
        assert truth.ids[-1] == -1 and np.allclose(truth.uv[-1], SPOT[:2])
        assert np.array_equal(truth.uv[:-1], truth0.uv)
        u, v, flux = _cog(img, *SPOT[:2])
        assert abs(u - SPOT[0]) < 0.05 and abs(v - SPOT[1]) < 0.05
        # same flux as a star of the same magnitude: the moving catalog star's window
        us, vs, flux_star = _cog(img, *truth.uv[0])
        assert abs(flux / flux_star - 1) < 0.02
        # without the glint the spot's pixels hold only background
        assert _cog(img0, *SPOT[:2])[2] < 0.05 * flux


def test_windows_see_the_glint_as_the_full_frame_does():
    cat = one_star_catalog([0.0, 0.0, 1.0])
    sky = Sky(cat, "xing2012", seed=5, false_spots=[SPOT])
    img, _ = sky.render_frame(IDENTITY_Q, np.zeros(3), frame=7)
    spans = np.array([[0, r, 295, 306] for r in range(606, 618)], np.int32)
    pix, _ = sky.render_windows(spans, IDENTITY_Q, np.zeros(3), frame=7)
    assert np.array_equal(pix, np.concatenate([img[r, a:b] for _, r, a, b in spans]))


def test_head_emulator_renders_the_glints_at_any_exposure():
    """The emulator's sky for an exposure (a new Sky per exposure time) keeps the scenario's
    glints: a window on the glint reads its light, as the plain sky renders it."""
    from gyrostar.clock import SimulatedClock
    from gyrostar.mocks.head_emulator import ConstantRateScene, HeadEmulator

    cat = one_star_catalog([0.0, 0.0, 1.0], vmag=4.5)
    sky = Sky(cat, "xing2012", seed=3, false_spots=[SPOT])
    emu = HeadEmulator(sky, ConstantRateScene(IDENTITY_Q, t0=0.0), clock=SimulatedClock(0.0), noise=False)
    u, v = int(round(SPOT[0])), int(round(SPOT[1]))
    spans = np.array([[0, r, u - 5, u + 6] for r in range(v - 5, v + 6)], np.int32)
    for exposure_us in (10_000, 5_000):
        px = emu.render_windows(spans, 0.0, 1, exposure_us).astype(float)
        ref = sky.with_exposure(exposure_us * 1e-6).window_pixels(spans, IDENTITY_Q, np.zeros(3), frame=1,
                                                                  noise=False)
        assert np.array_equal(px, np.minimum(ref, 0x3FF))
        signal = (px - np.median(px)).clip(0).sum() * 5.0        # e- (xing2012: 5 e-/ADU)
        assert signal > 0.8 * float(sky.preset.with_exposure(exposure_us * 1e-6).star_electrons(SPOT[2]))
