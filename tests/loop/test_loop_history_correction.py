"""An update corrects the attitude history from its mid-exposure on, so a frame exposed
before an earlier frame's update was applied (streaming at speed: pixels arrive ~9–11 ms
after mid-exposure at 100 frames/s) is carried to now through corrected attitudes and does
not apply the same correction twice."""

import numpy as np
from gyrostar.attitude import quat_conj, quat_mult, quat_to_dcm, rotvec_to_quat
from gyrostar.loop import record as R
from gyrostar.loop.attitude_filter import AttitudeFilter

PERIOD = 0.0025
W = np.radians([0.0, 5.0, 0.0])          # a 5 °/s slew about body y


class _Samples:
    def __init__(self, t, rate):
        self.t, self.rate = t, rate
        self.flags = np.zeros(len(t), np.uint8)
        self.n = len(t)


def _run(f, t0, n):
    t = t0 + np.arange(n) * PERIOD
    f.predict(_Samples(t, np.tile(W, (n, 1))), 0, R.FLAG_ATTITUDE_VALID, R.MODE_TRACK,
              np.zeros((0, 3)), np.zeros(0, np.int32), np.zeros(10), np.zeros(0, np.int64),
              np.zeros((R.MAX_STARS, 2)), R.empty(n))
    return t


def _stars(q_true, n=12, seed=0):
    """Catalog directions (ICRS) and their body directions under ``q_true`` (no noise)."""
    rng = np.random.default_rng(seed)
    body = rng.normal(size=(n, 3)) * 0.05 + [0, 0, 1.0]
    body /= np.linalg.norm(body, axis=1)[:, None]
    refs = body @ quat_to_dcm(q_true)          # body = R refs
    return body, refs


def test_history_after_an_update_holds_the_mid_exposure_product():
    f = AttitudeFilter(1e-5, 1e-9, 1e-4, PERIOD)
    f.ts[0] = -PERIOD
    f.P[:3, :3] = np.eye(3) * (20 / 206265) ** 2
    f.valid = True
    _run(f, 0.0, 40)                               # estimate = truth propagated, truth = offset by 20″
    t_mid = 0.0725                                 # a frame exposed 2.5 ms before the newest sample
    q_est_mid = f.q_at(t_mid)
    q_true_mid = quat_mult(rotvec_to_quat(np.array([20, -15, 0]) / 206265), q_est_mid)
    body, refs = _stars(q_true_mid)
    acc = np.zeros(len(body), np.uint8)
    n = f.update(t_mid, body, refs, np.full(len(body), 1e-6), acc)
    assert n == len(body)
    # the attitude history at t_mid is the filtered mid-exposure product, not the old prior
    np.testing.assert_allclose(f.q_at(t_mid), f.mid[1:5], atol=1e-12)
    err = quat_mult(f.q_at(t_mid), quat_conj(q_true_mid))
    assert np.linalg.norm(2 * err[:3]) * 206265 < 0.5


def test_a_frame_exposed_before_the_last_update_is_not_corrected_twice():
    """Frame A (mid 0.0650 s) is applied at 0.0975 s, after frame B's mid-exposure (0.0700 s);
    B, applied next, finds the attitude already right and must leave it there."""
    f = AttitudeFilter(1e-5, 1e-9, 1e-4, PERIOD)
    f.ts[0] = -PERIOD
    f.P[:3, :3] = np.eye(3) * (30 / 206265) ** 2
    f.valid = True
    _run(f, 0.0, 40)
    # the truth: the estimate's trajectory turned by a constant 30″ (ICRS side: propagation
    # multiplies on the body side, so truth and estimate share every gyro rotation)
    off = rotvec_to_quat(np.array([0.0, 30.0, 0.0]) / 206265)
    truth = {t: quat_mult(f.q_at(t), off) for t in (0.065, 0.070)}
    q_true_now = quat_mult(f.q.copy(), off)
    sig = 20 / 206265                  # per star: after A the attitude is known to ~6″, so B's
    for t_mid in (0.065, 0.070):       # stars pass their gates whether B is carried right or not
        body, refs = _stars(truth[t_mid], seed=int(t_mid * 1e3))
        acc = np.zeros(len(body), np.uint8)
        assert f.update(t_mid, body, refs, np.full(len(body), sig), acc) == len(body)
    err = quat_mult(f.q, quat_conj(q_true_now))
    # noise-free stars: A leaves ~1″ (its prior's share), B less; carried through the
    # uncorrected history B applies A's 29″ correction a second time (14.7″ off)
    assert np.linalg.norm(2 * err[:3]) * 206265 < 1.0


def test_overlapping_updates_keep_the_walk_since_mid_exposure():
    """Frame B is exposed before frame A's update is applied (100 frames/s, pixels ~9 ms late).
    The prior at B's mid-exposure is P − N²·lag > 0 however small the posterior of A is, and
    B's posterior carried to now holds the walk N²(lag − κ) since its mid-exposure: NEES after
    an update was 2–2.5 in real time when a 2·N²·lag margin sent such updates down the
    no-prior branch (no walk added back)."""
    arw = 2e-4                                   # rad/√s
    f = AttitudeFilter(arw, 1e-9, 1e-4, PERIOD, lowpass_hz=47.0)
    f.ts[0] = -PERIOD
    f.P[:3, :3] = np.eye(3) * (5 / 206265) ** 2
    f.valid = True
    _run(f, 0.0, 41)                             # samples up to 0.100 s
    sig = 2 / 206265
    body, refs = _stars(f.q_at(0.0925), seed=1)
    f.update(0.0925, body, refs, np.full(len(body), sig), np.zeros(len(body), np.uint8))     # A
    _run(f, 0.1025, 4)                           # up to 0.110 s
    t_mid_b = 0.0975                             # B: exposed before A was applied at 0.100 s
    body, refs = _stars(f.q_at(t_mid_b), seed=2)
    lag = f.t_last - t_mid_b
    assert f.update(t_mid_b, body, refs, np.full(len(body), sig), np.zeros(len(body), np.uint8)) == len(body)
    p_mid = f.mid[5:].reshape(3, 3)
    walk = arw ** 2 * (lag - f.kappa)
    np.testing.assert_allclose(np.diag(f.P)[:3], np.diag(p_mid) + walk, rtol=0.02)


def test_a_delayed_update_with_a_scale_error_equals_one_at_mid_exposure():
    """With a rate-proportional error the walk since mid-exposure is not linear in time: the
    error grows from the last fix. An update measured at t_mid and applied 7.5 ms later must
    leave the covariance that the same update applied at t_mid and carried on by the gyro
    leaves: the prior at t_mid takes out the error's growth since t_mid, and the new fix
    restarts it there."""
    arw, ss = 2e-4, 0.004                        # rad/√s; rad/rad (0.4 %)
    sig = 2 / 206265
    t_mid = 0.0925

    def filt():
        f = AttitudeFilter(arw, 1e-12, 1e-9, PERIOD, rate_error=ss)
        f.ts[0] = -PERIOD
        f.ts[4] = -PERIOD                        # fixed at the start
        f.P[:3, :3] = np.eye(3) * (5 / 206265) ** 2
        f.valid = True
        return f

    a = filt()                                   # applied at t_mid, then carried on to 0.100 s
    _run(a, 0.0, 38)                             # samples to 0.0925 s
    assert a.t_last == t_mid
    body, refs = _stars(a.q_at(t_mid), seed=3)
    a.update(t_mid, body, refs, np.full(len(body), sig), np.zeros(len(body), np.uint8))
    _run(a, 0.095, 3)
    b = filt()                                   # applied at 0.100 s
    _run(b, 0.0, 41)
    assert b.update(t_mid, body, refs, np.full(len(body), sig), np.zeros(len(body), np.uint8)) == len(body)
    np.testing.assert_allclose(b.P[:3, :3], a.P[:3, :3], rtol=1e-6, atol=1e-9 * a.P[0, 0])
    assert b.ts[4] == a.ts[4] == t_mid
    # the growth since the fix is the scale error's, (σ_s |ω| lag)², besides the walk
    grow = (ss * np.linalg.norm(W) * 0.0075) ** 2
    assert grow > 1e-3 * a.P[0, 0]               # large enough for the check above to see it
