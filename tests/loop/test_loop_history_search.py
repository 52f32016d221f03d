"""The attitude history's search (the delayed update's prior at mid-exposure, and the
correction carried forward from it): walking back from the ring's head while the ring is in
time order gives what a scan of the whole ring gives, wrapped or not; a ring written out of
time order is scanned whole. Truth: a brute-force search written here."""

import numpy as np
from gyrostar.attitude import quat_propagate
from gyrostar.loop.update_kernel import q_at_history


def _ring(times, H):
    """A ring of H entries written with ``times`` in order (head at the last write), each
    entry's quaternion a distinct unit vector; ``ih[2]`` counts writes out of time order."""
    hist_t = np.full(H, -np.inf)
    hist_q = np.zeros((H, 4))
    ih = np.array([H - 1, 0, 0], np.int64)
    rng = np.random.default_rng(len(times))
    for t in times:
        if t <= hist_t[ih[0]]:
            ih[2] += 1
        ih[0] = (ih[0] + 1) % H
        hist_t[ih[0]] = t
        q = rng.standard_normal(4)
        hist_q[ih[0]] = q / np.linalg.norm(q)
    return hist_t, hist_q, ih


def _brute(hist_t, hist_q, rate, t):
    """The latest entry at or before t (the first in array order among equal times), carried to t."""
    cand = [(hist_t[i], -i) for i in range(len(hist_t)) if hist_t[i] != -np.inf and hist_t[i] <= t]
    if not cand:
        return None
    i = -max(cand)[1]
    return quat_propagate(hist_q[i], rate, t - hist_t[i])


def _check(times, H, queries):
    hist_t, hist_q, ih = _ring(times, H)
    q_now = np.array([0.0, 0.0, 0.0, 1.0])
    ts = np.array([times[-1], 0.01, -0.02, 0.005])      # [t of the last sample, rate (rad/s)]
    for t in queries:
        want = _brute(hist_t, hist_q, ts[1:], t)
        got = q_at_history(q_now, ts, hist_t, hist_q, ih, float(t))
        assert np.array_equal(got, q_now if want is None else want), (t, ih)
    return ih


def test_in_order_ring_partly_filled_and_wrapped():
    rng = np.random.default_rng(1)
    for n in (5, 64, 300):                                 # 64-entry ring: 300 writes wrap it
        times = np.cumsum(rng.uniform(0.001, 0.004, n))
        queries = np.concatenate([times, times - 1e-4, [times[0] - 1.0, times[-1] + 1.0],
                                  rng.uniform(times[0] - 0.01, times[-1] + 0.01, 50)])
        assert _check(times, 64, queries)[2] == 0


def test_out_of_order_ring_is_scanned_whole():
    rng = np.random.default_rng(2)
    times = np.cumsum(rng.uniform(0.001, 0.004, 100))
    times[40], times[41] = times[41], times[40]            # one step back in time
    times[70] = times[69]                                  # and a repeated stamp
    ih = _check(times, 64, np.concatenate([times, rng.uniform(times[0], times[-1], 80)]))
    assert ih[2] == 2
