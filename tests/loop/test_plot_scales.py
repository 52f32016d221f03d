"""Run and campaign figures take their scale from the data and say what they leave out: roll
on its own panel (it was clipped to the cross-boresight scale with no note), centroid errors at
their own size (fixed ±1 px), the campaign's error CDF over the errors' span (always 10⁻²–10⁵″)."""

import numpy as np
from gyrostar.hil import plots
from gyrostar.hil.montecarlo.metrics import ERR_EDGES_ARCSEC
from gyrostar.hil.montecarlo.plots import cdf_span
from gyrostar.loop import record as R


def _run(n=2000, cross=3.0, roll=40.0):
    rng = np.random.default_rng(2)
    out = R.empty(n)
    out["t"] = np.arange(n) / 400.0
    out["mode"] = R.MODE_TRACK
    out["q"] = [0.0, 0.0, 0.0, 1.0]
    truth = np.zeros(n, [("q", "<f8", (4,)), ("bias", "<f8", (3,))])
    rot = np.radians(np.column_stack([rng.normal(0, cross, n), rng.normal(0, cross, n), rng.normal(0, roll, n)])
                     / 3600.0)
    truth["q"][:, :3] = rot / 2.0
    truth["q"][:, 3] = np.sqrt(1.0 - (truth["q"][:, :3] ** 2).sum(axis=1))
    return out, truth


def test_roll_has_its_own_panel_and_scale(tmp_path):
    from matplotlib.image import imread

    out, truth = _run()
    path = plots._attitude_error(tmp_path, out, truth, None)
    assert imread(path).shape[0] > 600                     # two panels (one panel was 440 px tall)
    err = plots.attitude_errors(out, truth) * plots.ARCSEC
    lim_cross, lim_roll = plots._symmetric_limit(err[:, :2], 5.0), plots._symmetric_limit(err[:, 2], 5.0)
    assert np.mean(np.abs(err[:, 2]) <= lim_roll) > 0.999      # roll shown, not clipped
    assert np.mean(np.abs(err[:, 2]) > lim_cross) > 0.5        # ... as the shared scale clipped it


def test_clip_note_counts_what_is_off_the_axis():
    err = np.array([0.1, -0.2, 0.05, 2.5])
    assert plots._clip_note(err, 0.8) == " (1 beyond ±0.8, max 2.5)"
    assert plots._clip_note(err[:3], 0.8) == ""


def test_centroid_scale_follows_the_errors():
    small = np.random.default_rng(1).normal(0, 0.02, (5000, 2))
    assert 0.05 <= plots._symmetric_limit(small, 0.05) < 0.3      # was ±1 px: errors of 0.02 px invisible
    large = small * 100
    assert plots._symmetric_limit(large, 0.05) > 5.0


def test_error_cdf_spans_the_errors():
    hist = np.zeros(len(ERR_EDGES_ARCSEC) - 1)
    hist[1:] = np.histogram(np.random.default_rng(3).lognormal(np.log(3.0), 0.5, 100_000), ERR_EDGES_ARCSEC)[0][1:]
    lo, hi = cdf_span(hist)
    assert 0.1 < lo < 1.0 and 10.0 < hi < 100.0                    # 3″ errors: not 0.01 … 100000″
    assert cdf_span(np.zeros_like(hist)) == (ERR_EDGES_ARCSEC[1], ERR_EDGES_ARCSEC[-1])
