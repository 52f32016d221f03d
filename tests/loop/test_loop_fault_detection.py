"""Fault detection in the measurement of a frame's windows (issue 50): glare and blinding are
told from stars, against independent truth — windows built here by hand (a Gaussian PSF of
known flux and position, Gaussian read noise) with a bright background added at known pixels.
"""

import math

import numpy as np
import pytest
from gyrostar.loop import record as R
from gyrostar.loop.image_kernels import MEAS_BRIGHT, MEAS_MISS, MEAS_OK, measure_windows

F_PX = 2000.0
W = H = 256
CAM = np.array([F_PX, 127.5, 127.5, 0, 0, 0, 0, 0, W, H], np.float64)
BIAS_DN = 100.0
NOISE_DN = 3.0
PSF = 0.85
ZERO_DN = 20000.0          # DN of a V = 0 star in one exposure
BRIGHT_DN = 0.75 * 1023


def star_dn(v):
    return ZERO_DN * 10 ** (-0.4 * v)


class Frame:
    """Square windows of ``k`` px around given star positions, pixels in span order."""

    def __init__(self, centres, k=12, seed=0):
        self.rng = np.random.default_rng(seed)
        spans, self.boxes = [], []
        for w, (u, v) in enumerate(centres):
            r0, c0 = int(round(v)) - k // 2, int(round(u)) - k // 2
            self.boxes.append((r0, c0, k))
            spans += [[w, r, c0, c0 + k] for r in range(r0, r0 + k)]
        self.spans = np.array(spans, np.int32)
        self.img = np.full((H, W), BIAS_DN)

    def star(self, u, v, flux):
        yy, xx = np.mgrid[0:H, 0:W]
        # pixel-integrated Gaussian, well sampled at 0.85 px: 5×5 sub-pixels per pixel
        acc = np.zeros((H, W))
        for du in np.linspace(-0.4, 0.4, 5):
            for dv in np.linspace(-0.4, 0.4, 5):
                acc += np.exp(-((xx + du - u) ** 2 + (yy + dv - v) ** 2) / (2 * PSF ** 2))
        self.img += flux * acc / acc.sum()

    def values(self):
        img = self.img + self.rng.normal(0.0, NOISE_DN, self.img.shape)
        img = np.clip(np.round(img), 0, 1023)
        return np.concatenate([img[r, c0:c1] for _, r, c0, c1 in self.spans]).astype(np.float64)

    def measure(self, vmag):
        n = len(self.boxes)
        off = np.zeros((4 * n, 2))
        off_start = np.arange(n, dtype=np.int64) * 4
        off_len = np.full(n, 4, np.int64)
        return measure_windows(self.spans, self.values(), np.arange(n, dtype=np.int64), off, off_start, off_len, CAM,
                               PSF, 4.0, 30.0, 5.0, 10, 1e-3, np.asarray(vmag, np.float64), BRIGHT_DN)


def direction(u, v):
    d = np.array([(u - CAM[1]) / F_PX, (v - CAM[2]) / F_PX, 1.0])
    return d / np.linalg.norm(d)


CENTRES = [(40.3, 50.6), (120.7, 80.2), (200.1, 60.9), (70.5, 190.4), (180.8, 200.3)]
VMAG = [3.0, 4.0, 4.5, 5.0, 3.5]


def clean_frame(seed=0):
    fr = Frame(CENTRES, seed=seed)
    for (u, v), m in zip(CENTRES, VMAG):
        fr.star(u, v, star_dn(m))
    return fr


def test_clean_stars_are_all_measured_where_they_are():
    for seed in range(5):
        state, b, sig = clean_frame(seed).measure(VMAG)
        assert np.all(state == MEAS_OK), state
        for i, (u, v) in enumerate(CENTRES):
            err = math.acos(min(1.0, float(b[i] @ direction(u, v))))
            assert err < 4 * sig[i] + 1e-9, (i, err / sig[i])


def test_background_near_full_scale_is_bright_not_a_miss():
    fr = clean_frame()
    fr.img[40:60, 30:50] += 750.0          # glare over star 0's window
    fr.img[70:90, 110:130] += 300.0        # raised but measurable over star 1's
    state, _, sig = fr.measure(VMAG)
    assert state[0] == MEAS_BRIGHT
    assert state[1] == MEAS_OK
    fr.img[:, :] = BIAS_DN + 900.0         # the whole frame blinded
    state, _, _ = fr.measure(VMAG)
    assert np.all(state == MEAS_BRIGHT)
    assert MEAS_MISS not in state


def test_reason_code_rides_in_the_top_bits_of_the_flags():
    flags = np.array([R.FLAG_ATTITUDE_VALID | (R.REASON_BLINDED << R.REASON_SHIFT), R.FLAG_GYRO_STUCK], np.uint16)
    assert list(R.reason(flags)) == [R.REASON_BLINDED, R.REASON_NONE]
    used = 0
    for bit in R.FLAG_NAMES:
        used |= bit
    assert used & R.REASON_MASK == 0, "no quality flag in the reason bits"


@pytest.mark.parametrize("bright", [True, False])
def test_lost_in_space_does_not_search_a_blinded_full_frame(bright):
    from gyrostar.loop.coupled import LoopParams
    from gyrostar.loop.image import ImagePipeline

    class Cam:
        def as_array(self):
            return CAM

    class NoId:
        calls = 0

        def identify(self, uv):
            NoId.calls += 1
            return None

    fr = clean_frame()
    img = fr.img.copy()
    if bright:
        img[:, :40] = 1023.0                   # the Sun's glare over a sixth of the frame
    spots, ident, blinded = ImagePipeline(LoopParams(), Cam(), NoId(), threaded=False).lost_in_space(img)
    assert blinded == bright
    assert (NoId.calls == 0) == bright
    if not bright:
        assert len(spots) == 5
