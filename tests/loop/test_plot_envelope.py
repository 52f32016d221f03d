"""Run-plot trace reduction (hil.plots.envelope / band_envelope): what a pixel column shows
of a dense trace — every column's extremes, in order, NaN gaps kept — checked sample by
sample against the full trace."""

import numpy as np
import pytest
from gyrostar.hil.plots import band_envelope, envelope, scatter_sample


def _columns(n, columns):
    per = n // columns
    return [slice(c * per, (c + 1) * per) for c in range(columns)], per * columns


def test_envelope_keeps_each_columns_extremes_in_order():
    rng = np.random.default_rng(3)
    n, columns = 24_013, 100
    x = np.arange(n) / 400.0
    y = np.cumsum(rng.normal(size=n))
    ex, ey = envelope(x, y, columns)
    cols, m = _columns(n, columns)
    assert len(ey) == 2 * columns + (n - m)
    for c, sl in enumerate(cols):
        seg = y[sl]
        pair = ey[2 * c:2 * c + 2]
        assert sorted(pair) == [seg.min(), seg.max()]
        # the one that came first is drawn first
        assert (pair[0] == seg.min()) == (np.argmin(seg) <= np.argmax(seg))
        assert ex[2 * c] == x[sl][0] and ex[2 * c + 1] == x[sl][-1]
    # the samples after the last whole column are kept as they are
    assert np.array_equal(ey[2 * columns:], y[m:]) and np.array_equal(ex[2 * columns:], x[m:])
    # the drawn line spans exactly the trace's range
    assert ey.min() == y.min() and ey.max() == y.max()


def test_envelope_keeps_gaps_and_ignores_nan_inside_a_column():
    n, columns = 4000, 100
    x = np.arange(n, dtype=float)
    y = np.sin(x / 50.0)
    y[400:800] = np.nan          # whole columns 10..19: a gap in the line
    y[1005] = np.nan             # one sample of column 25: its extremes come from the rest
    ex, ey = envelope(x, y, columns)
    assert np.isnan(ey[20:40]).all()
    seg = y[1000:1040]
    assert sorted(ey[50:52]) == [np.nanmin(seg), np.nanmax(seg)]
    assert np.isfinite(np.delete(ey, np.s_[20:40])).all()


def test_short_traces_come_back_untouched():
    x = np.arange(1000.0)
    y = x ** 2
    ex, ey = envelope(x, y, 400)
    assert ex is x and ey is y
    bx, lo, hi = band_envelope(x, y - 1, y + 1, 400)
    assert bx is x


@pytest.mark.parametrize("n", [24_000, 24_019])
def test_band_envelope_covers_every_sample(n):
    rng = np.random.default_rng(7)
    columns = 150
    x = np.arange(n) / 400.0
    mid = np.cumsum(rng.normal(size=n)) * 0.1
    half = np.abs(rng.normal(size=n)) + 0.5
    bx, lo, hi = band_envelope(x, mid - half, mid + half, columns)
    # every sample's band lies inside the band drawn as steps ("post": each point's value
    # held to the next point) over the sample's x
    step = np.searchsorted(bx, x, side="right") - 1
    assert (lo[step] <= mid - half).all() and (hi[step] >= mid + half).all()
    assert bx[0] == x[0] and bx[-1] == x[-1] and (np.diff(bx) >= 0).all()
    # and the drawn band is no wider than the samples' own extremes
    assert lo.min() == (mid - half).min() and hi.max() == (mid + half).max()


def test_scatter_sample_keeps_every_kth_and_all_outliers():
    rng = np.random.default_rng(11)
    err = rng.normal(size=(250_000, 2)) * 0.1
    err[12_346, 1] = 0.9                      # an outlier off the regular sample
    rms = float(np.sqrt(np.mean(err ** 2)))
    rows, every = scatter_sample(err, rms, most=100_000)
    assert every == 3
    beyond = np.flatnonzero((np.abs(err) > 3 * rms).any(axis=1))
    assert 12_346 in rows and 12_346 % 3 != 0
    assert set(beyond) <= set(rows) and set(range(0, 250_000, 3)) <= set(rows)
    assert len(rows) == len(set(range(0, 250_000, 3)) | set(beyond))
    # small scatters are drawn whole
    rows, every = scatter_sample(err[:1000], rms)
    assert every == 1 and np.array_equal(rows, np.arange(1000))
