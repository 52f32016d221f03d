"""Row-span windows and centroiding against hand-built truth."""

import numpy as np
import pytest
from gyrostar.core.centroid import (
    background_far,
    centroid_variance,
    cog,
    iwcog,
    iwcog_variance,
    smear_fit,
    window_background,
    window_spans_of,
)
from gyrostar.core.windows import concat_windows, fixed_window, span_pixel_count, trajectory_window


def spans_to_mask(spans, n_rows, n_cols):
    m = np.zeros((n_rows, n_cols), dtype=int)
    for _, r, c0, c1 in spans:
        m[r, c0:c1] += 1
    return m


def test_fixed_window_even_and_odd_sizes():
    s = fixed_window(10.2, 19.8, 6, 64, 64, 3)
    assert s.dtype == np.int32 and s.shape == (6, 4)
    assert np.all(s[:, 0] == 3)
    # an even square's centre is a pixel corner: the nearest one to (10.2, 19.8) is (10.5, 19.5)
    np.testing.assert_array_equal(s[:, 1], np.arange(17, 23))
    np.testing.assert_array_equal(s[0, 2:], [8, 14])
    s5 = fixed_window(10.0, 10.0, 5, 64, 64, 0)
    np.testing.assert_array_equal(s5[:, 1], np.arange(8, 13))
    np.testing.assert_array_equal(s5[0, 2:], [8, 13])


def test_fixed_window_clipped_and_off_sensor():
    s = fixed_window(1.0, 62.5, 6, 64, 64, 0)
    m = spans_to_mask(s, 64, 64)
    assert m.sum() == 5 * 4 and m.max() == 1  # cols -1..4 -> 0..4, rows 60..65 -> 60..63
    assert fixed_window(-20.0, 5.0, 6, 64, 64, 0).shape == (0, 4)


def test_trajectory_window_is_union_of_squares_along_path():
    traj = np.array([[20.0, 30.0], [31.7, 36.2]])  # diagonal smear of ~13 px
    spans = trajectory_window(traj, 6, 64, 64, 7)
    mask = spans_to_mask(spans, 64, 64)
    assert mask.max() == 1  # no overlapping spans
    truth = np.zeros((64, 64), dtype=int)
    for t in np.linspace(0, 1, 2000):  # brute force: union of squares on a dense path
        u, v = traj[0] + t * (traj[1] - traj[0])
        c0 = int(np.floor(u - 2.5 + 0.5))
        r0 = int(np.floor(v - 2.5 + 0.5))
        truth[r0:r0 + 6, c0:c0 + 6] = 1
    np.testing.assert_array_equal(mask, truth)
    # sorted by row, all ids set, half-open spans
    assert np.all(np.diff(spans[:, 1]) >= 0) and np.all(spans[:, 0] == 7)
    assert span_pixel_count(spans) == truth.sum()


def test_trajectory_window_clipped_to_sensor_and_u_turn():
    traj = np.array([[2.0, 2.0], [-5.0, 2.0]])
    spans = trajectory_window(traj, 6, 32, 32, 0)
    assert spans[:, 2].min() == 0 and spans[:, 1].min() == 0
    # a U-shaped path leaves two runs on some rows
    u = np.array([[10.0, 10.0], [10.0, 25.0], [25.0, 25.0], [25.0, 10.0]])
    spans = trajectory_window(u, 4, 64, 64, 0)
    rows, counts = np.unique(spans[:, 1], return_counts=True)
    assert counts.max() == 2


def _squares_painted(traj, k, n_rows, n_cols):
    """Every k×k square at the window's 0.5 px resampling of ``traj``, painted whole into a
    sensor-sized mask (numpy, no shortcuts)."""
    mask = np.zeros((n_rows, n_cols), dtype=int)
    half = (k - 1) / 2.0
    for i in range(len(traj)):
        a = traj[i]
        b = traj[i + 1] if i + 1 < len(traj) else a
        ns = max(1, int(np.ceil(max(abs(b - a)) / 0.5)))
        for j in range(ns):
            u, v = a + j / ns * (b - a)
            c0 = int(np.floor(u - half + 0.5))
            r0 = int(np.floor(v - half + 0.5))
            mask[max(r0, 0):max(r0 + k, 0), max(c0, 0):max(c0 + k, 0)] = 1
    return mask


@pytest.mark.parametrize("shape", ["line", "curve", "jumps", "back-and-forth"])
def test_trajectory_window_equals_every_square_painted(shape):
    """The window paints only what each square adds to the one before it: the union must be
    that of every square, for any path (curling, jumping, reversing, leaving the sensor) and
    any side up to 40 px."""
    rng = np.random.default_rng(11)
    for _ in range(150):
        m = int(rng.integers(1, 40))
        k = int(rng.integers(1, 41))
        start = rng.uniform(-30, 130, 2)
        if shape == "line":
            traj = start + np.arange(m)[:, None] * rng.normal(size=2) * rng.uniform(0, 3)
        elif shape == "curve":
            ang = np.cumsum(rng.normal(0, 0.4, m))
            traj = start + np.cumsum(np.stack([np.cos(ang), np.sin(ang)], 1) * rng.uniform(0, 3), 0)
        elif shape == "jumps":
            traj = start + np.cumsum(rng.normal(0, 6, (m, 2)), 0)
        else:
            traj = start + np.sin(np.arange(m) * rng.uniform(0.2, 1.5))[:, None] * rng.normal(0, 8, 2)
        spans = trajectory_window(traj, k, 100, 120, 3)
        mask = spans_to_mask(spans, 100, 120)
        assert mask.max(initial=0) <= 1
        np.testing.assert_array_equal(mask, _squares_painted(traj, k, 100, 120))
        if len(spans):
            assert np.all(np.diff(spans[:, 1]) >= 0) and np.all(spans[:, 2] < spans[:, 3])


def test_concat_windows_sorted():
    a = fixed_window(30.0, 30.0, 6, 64, 64, 1)
    b = fixed_window(10.0, 10.0, 6, 64, 64, 0)
    s = concat_windows([a, b])
    assert s.dtype == np.int32 and s[0, 0] == 0 and s[-1, 0] == 1
    start, stop, first_val = window_spans_of(s, 1)
    assert (start, stop, first_val) == (6, 12, 36)


def gaussian_window(spans, u0, v0, sigma, flux, bg, rng, read=0.0):
    vals = []
    for _, r, c0, c1 in spans:
        for c in range(c0, c1):
            # pixel-integrated Gaussian via fine sampling
            su = np.linspace(c - 0.45, c + 0.45, 10)
            sv = np.linspace(r - 0.45, r + 0.45, 10)
            g = np.exp(-((su[None] - u0) ** 2 + (sv[:, None] - v0) ** 2) / (2 * sigma ** 2)).mean()
            vals.append(bg + flux * g / (2 * np.pi * sigma ** 2))
    vals = np.array(vals)
    if rng is not None:
        vals = rng.poisson(vals).astype(float) + rng.standard_normal(vals.size) * read
    return vals


def test_cog_noiseless_symmetric_spot_is_exact():
    spans = fixed_window(20.5, 15.5, 8, 64, 64, 0)  # spot centred in the window
    vals = gaussian_window(spans, 20.5, 15.5, 0.85, 5000.0, 100.0, None)
    u, v, flux, npix = cog(spans, vals, 100.0, 100.5)
    assert u == pytest.approx(20.5, abs=1e-9) and v == pytest.approx(15.5, abs=1e-9)
    assert npix > 4 and flux == pytest.approx(5000.0, rel=0.02)
    u, v, flux, _ = cog(spans, vals, 100.0, 1e9)
    assert np.isnan(u) and flux == 0.0


def test_background_estimate_and_variance_match_monte_carlo():
    rng = np.random.default_rng(1)
    spans = fixed_window(20.3, 15.8, 8, 64, 64, 0)
    us = []
    var_pred = []
    bgs = []
    clean = gaussian_window(spans, 20.3, 15.8, 0.85, 2000.0, 50.0, None)
    for _ in range(400):
        vals = rng.poisson(clean).astype(float) + rng.standard_normal(clean.size) * 10.0
        bg, sig, n = background_far(spans, vals, np.array([[20.3, 15.8]]), 2.5)
        bgs.append(bg)
        sig = np.sqrt(50.0 + 100.0)  # known read + background shot noise
        u, v, flux, npix = cog(spans, vals, bg, bg + 3 * sig)
        us.append(u)
        var_pred.append(centroid_variance(spans, vals, bg, bg + 3 * sig, u, v, sig, 1.0)[0])
    assert np.mean(bgs) == pytest.approx(50.0, abs=1.5)
    # the plain clipped window estimate is biased high by the star's wings
    assert window_background(vals, 3.0)[0] > 50.0
    emp = np.var(us)
    # the propagation ignores threshold selection: a lower bound within a factor of 3
    assert np.mean(var_pred) <= emp <= 3.0 * np.mean(var_pred)


def test_iwcog_smeared_spot_beats_cog_at_low_snr():
    """Smeared faint spot: trajectory-weighted CoG is unbiased and less noisy than CoG."""
    rng = np.random.default_rng(2)
    traj = np.array([[20.0, 20.0], [28.0, 23.0]])
    spans = trajectory_window(traj, 6, 64, 64, 0)
    t = np.linspace(0, 1, 41)
    pts = traj[0] + t[:, None] * (traj[1] - traj[0])
    centre = pts.mean(axis=0)
    offsets = pts[::4] - centre
    e_cog, e_iw, v_iw = [], [], []
    clean = np.zeros(span_pixel_count(spans))
    for p in pts:
        clean += gaussian_window(spans, p[0], p[1], 0.85, 1500.0 / len(pts), 0.0, None)
    for _ in range(300):
        vals = rng.poisson(clean + 30.0) + rng.standard_normal(clean.size) * 15.0
        bg, sig = 30.0, np.sqrt(30.0 + 225.0)  # known level and noise: compares the estimators only
        u, v, _, _ = cog(spans, vals, bg, bg + 2.0 * sig)
        e_cog.append([u, v] - centre)
        u, v, _, _ = iwcog(spans, vals, bg, centre[0] + 0.3, centre[1] - 0.3, offsets, 1.0, 20, 1e-4)
        e_iw.append([u, v] - centre)
        v_iw.append(iwcog_variance(spans, vals, bg, u, v, offsets, 1.0, np.sqrt(30.0 + 225.0), 1.0))
    e_cog, e_iw = np.array(e_cog), np.array(e_iw)
    assert np.abs(e_iw.mean(axis=0)).max() < 0.05
    assert np.sqrt((e_iw ** 2).mean()) < 0.9 * np.sqrt((e_cog ** 2).mean())
    # its error propagation agrees with the scatter (fixed-weight linear estimator)
    np.testing.assert_allclose(np.mean(v_iw, axis=0), e_iw.var(axis=0), rtol=0.3)


def test_smear_fit_is_unbiased_beats_iwcog_and_knows_its_variance():
    rng = np.random.default_rng(4)
    traj = np.array([[20.2, 20.7], [28.4, 24.1]])
    spans = trajectory_window(traj, 6, 64, 64, 0)
    t = np.linspace(0, 1, 41)
    pts = traj[0] + t[:, None] * (traj[1] - traj[0])
    centre = pts.mean(axis=0)
    offsets = np.ascontiguousarray(pts[::2] - centre)
    clean = np.zeros(span_pixel_count(spans))
    for p in pts:
        clean += gaussian_window(spans, p[0], p[1], 0.85, 2000.0 / len(pts), 0.0, None)
    e_fit, e_iw, v_fit = [], [], []
    noise_var = 20.0 + 225.0
    for _ in range(300):
        vals = rng.poisson(clean + 20.0) + rng.standard_normal(clean.size) * 15.0
        u, v, flux, vu, vv, it = smear_fit(spans, vals, 20.0, centre[0] + 0.4, centre[1] - 0.3, offsets, 0.85,
                                           noise_var, 1.0, 10, 1e-4)
        e_fit.append([u, v] - centre)
        v_fit.append([vu, vv])
        u, v, _, _ = iwcog(spans, vals, 20.0, centre[0], centre[1], offsets, 1.0, 30, 1e-4)
        e_iw.append([u, v] - centre)
    e_fit, e_iw = np.array(e_fit), np.array(e_iw)
    assert np.abs(e_fit.mean(axis=0)).max() < 0.03
    assert np.sqrt((e_fit ** 2).mean()) < 0.9 * np.sqrt((e_iw ** 2).mean())
    np.testing.assert_allclose(np.mean(v_fit, axis=0), e_fit.var(axis=0), rtol=0.25)


def test_window_bad_inputs_are_config_errors():
    from gyrostar.errors import ConfigError

    with pytest.raises(ConfigError):
        trajectory_window(np.zeros((3, 2)), 0, 64, 64, 0)
    with pytest.raises(ConfigError):
        trajectory_window(np.zeros((3, 3)), 6, 64, 64, 0)
    with pytest.raises(ConfigError):
        fixed_window(np.nan, 3.0, 6, 64, 64, 0)


def test_smear_fit_erf_and_pdf_match_the_library_within_the_stated_bound():
    """The fit's one-exponential erf (A&S 7.1.26) against math.erf, and its pdf against the
    Gaussian's: |Δerf| ≤ 1.5e-7 (its published bound) over the pixel edges a window spans."""
    import math

    from gyrostar.core.centroid import erf_pdf

    sigma = 0.85
    inv_s = 1.0 / (math.sqrt(2.0) * sigma)
    k_pdf = 1.0 / (sigma * math.sqrt(2.0 * math.pi))
    worst = 0.0
    for z in np.linspace(-12.0, 12.0, 4801):
        e, p = erf_pdf(z, inv_s, k_pdf)
        worst = max(worst, abs(e - math.erf(z * inv_s)))
        assert abs(p - k_pdf * math.exp(-0.5 * (z / sigma) ** 2)) <= 1e-15
    assert 1e-9 < worst <= 1.5e-7


def _background_reference(values, clip):
    """window_background written out with numpy sorts: median/MAD, then two 3σ clips."""
    v = np.sort(np.asarray(values, float))
    med = float(np.median(v))
    sig = 1.4826 * float(np.sort(np.abs(v - med))[len(v) // 2]) or 1.0
    for _ in range(2):
        kept = v[v < med + clip * sig]
        if len(kept) < 3:
            break
        med = float(np.sum(kept)) / len(kept)
        sig = float(np.sqrt(max(float(np.sum(kept * kept)) / len(kept) - med * med, 1e-12)))
    return med, sig


def test_window_background_by_hand():
    """9 pixels, one star pixel: median 11, MAD 1 → clip at 11 + 3·1.4826 drops the 200;
    the 8 left have mean 11 and variance 980/8 − 121 = 1.5."""
    bg, sig = window_background(np.array([10, 12, 11, 10, 13, 200, 11, 12, 9], float), 3.0)
    assert bg == 11.0 and sig == pytest.approx(np.sqrt(1.5), rel=1e-15)
    # an even count takes the mean of the middle two as the median (10.5; MAD 0.5)
    assert window_background(np.array([10, 11, 10, 11], float), 3.0) == (10.5, 0.5)


@pytest.mark.parametrize("dtype", [np.float64, np.uint16])
def test_window_background_integer_windows_match_the_sorted_estimate(dtype):
    """ADU windows (integers: counted in a histogram) give the sorted estimate to the bit,
    from flat windows to star windows with a wide dynamic range; non-integer windows and
    windows spanning more levels than the histogram takes go the sorting way."""
    rng = np.random.default_rng(7)
    for n in list(range(1, 60)) + [112, 300, 528]:
        for _ in range(20):
            base = np.round(rng.normal(rng.uniform(20, 200), rng.uniform(0.0, 15.0), n))
            star = (rng.random(n) < 0.15) * rng.integers(0, 4000, n)
            vals = np.clip(base + star, 0, 65535).astype(dtype)
            assert window_background(vals, 3.0) == _background_reference(vals, 3.0)
    halves = np.round(rng.normal(100, 5, 50)) + 0.5
    assert window_background(halves, 3.0) == pytest.approx(_background_reference(halves, 3.0), rel=1e-15)
    wide = rng.integers(0, 60000, 40).astype(float)
    assert window_background(wide, 3.0) == pytest.approx(_background_reference(wide, 3.0), rel=1e-15)
