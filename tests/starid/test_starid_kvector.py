"""k-vector range search against brute force."""

import numpy as np
import pytest
from gyrostar.errors import ConfigError
from gyrostar.starid import kvector


@pytest.mark.parametrize("dist", ["uniform", "sine", "clustered"])
def test_query_equals_brute_force(dist):
    rng = np.random.default_rng(3)
    if dist == "uniform":
        y = rng.uniform(0.0, 0.2, 5000)
    elif dist == "sine":  # star-pair angles: density ∝ sin θ
        y = np.arccos(1.0 - rng.uniform(0.0, 1.0 - np.cos(0.25), 5000))
    else:
        y = np.concatenate([rng.normal(0.05, 1e-4, 2500), rng.uniform(0.0, 0.1, 2500)])
    y = np.sort(y)
    k, m, q = kvector.build(y)
    for _ in range(300):
        lo = rng.uniform(y[0] - 0.01, y[-1])
        hi = lo + rng.uniform(0.0, 0.01)
        s, e = kvector.query(y, k, m, q, lo, hi)
        want = np.flatnonzero((y >= lo) & (y <= hi))
        if want.size:
            assert (s, e) == (want[0], want[-1] + 1)
        else:
            assert s == e
    # the extremes and an empty range
    assert kvector.query(y, k, m, q, y[0], y[-1]) == (0, y.size)
    assert kvector.query(y, k, m, q, 1.0, 2.0)[0] == kvector.query(y, k, m, q, 1.0, 2.0)[1]


def test_build_rejects_bad_input():
    with pytest.raises(ConfigError):
        kvector.build(np.array([0.3, 0.1, 0.2]))
    with pytest.raises(ConfigError):
        kvector.build(np.array([0.1]))
