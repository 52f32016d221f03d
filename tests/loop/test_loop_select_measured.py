"""The image update's selection of measured stars and its consistency check, against
hand-built windows and a reference written here from ``verify_matches``."""

import math

import numpy as np
from gyrostar.attitude import quat_from_boresight, quat_to_dcm
from gyrostar.loop.image_kernels import MEAS_ABSENT, MEAS_MISS, MEAS_OK, select_measured
from gyrostar.starid.verify import consistent, verify_matches


def test_selection_skips_refilled_slots_counts_misses_and_coasts():
    wins = np.array([1, 3, 4, 6], np.int64)
    planned = np.array([10, 30, 40, 60], np.int64)
    nav = np.array([-1, 10, -1, 31, 40, -1, 60], np.int64)        # slot 3 now tracks another star
    active = np.array([False, True, False, True, True, False, True])
    state = np.array([MEAS_OK, MEAS_OK, MEAS_MISS, MEAS_OK], np.int8)
    b = np.arange(12, dtype=np.float64).reshape(4, 3)
    refs = np.arange(21, dtype=np.float64).reshape(7, 3) * 10
    sig = np.array([3e-5, 4e-5, 5e-5, 6e-5])
    misses = np.zeros(7, np.int64)
    slots, bu, ru, su = select_measured(wins, planned, state, b, sig, active, nav, misses, refs, 0.0, False)
    assert slots.tolist() == [1, 6]
    assert np.array_equal(bu, b[[0, 3]]) and np.array_equal(ru, refs[[1, 6]])
    assert np.array_equal(su, sig[[0, 3]])
    assert misses.tolist() == [0, 0, 0, 0, 1, 0, 0]              # slot 4 missed its spot
    cam_var = (0.02 / 6640.0) ** 2
    _, _, _, su = select_measured(wins, planned, state, b, sig, active, nav, misses, refs, cam_var, False)
    assert np.allclose(su, np.sqrt(sig[[0, 3]] ** 2 + cam_var), rtol=1e-15)
    assert misses[4] == 2
    slots, *_ = select_measured(wins, planned, state, b, sig, active, nav, misses, refs, 0.0, True)
    assert len(slots) == 0 and misses[4] == 3                     # turning too fast: none taken, misses still count
    state[:] = MEAS_ABSENT
    slots, *_ = select_measured(wins, planned, state, b, sig, active, nav, misses, refs, 0.0, False)
    assert len(slots) == 0 and misses[4] == 3                     # a window not read is no miss


def _reference(b, ref, sig, k, tol_min):
    n = len(sig)
    if n < 3:
        return np.ones(n, bool)
    _, match, n_ok, _ = verify_matches(b, ref, np.arange(n, dtype=np.int64), max(k * float(np.median(sig)), tol_min))
    return match >= 0 if n_ok else np.zeros(n, bool)


def test_consistent_drops_the_star_that_disagrees():
    rng = np.random.default_rng(3)
    a = quat_to_dcm(quat_from_boresight(1.0, 0.4, 0.2))
    for n in (2, 3, 5, 8, 12):
        ref = rng.standard_normal((n, 3)) * 0.05 + a[2]
        ref /= np.linalg.norm(ref, axis=1)[:, None]
        b = ref @ a.T + rng.standard_normal((n, 3)) * 2e-6
        b /= np.linalg.norm(b, axis=1)[:, None]
        if n >= 5:
            b[1] = b[1] + np.array([3e-4, -2e-4, 0.0])          # one window caught something else
            b[1] /= np.linalg.norm(b[1])
        sig = rng.uniform(2e-6, 6e-6, n)
        got = consistent(b, ref, sig, 6.0, 1.5 / 6640.0)
        assert np.array_equal(got, _reference(b, ref, sig, 6.0, 1.5 / 6640.0))
        if n >= 5:
            assert not got[1] and got.sum() == n - 1
        else:
            assert got.all()
    assert math.isclose(float(np.median([1.0, 3.0])), 2.0)
