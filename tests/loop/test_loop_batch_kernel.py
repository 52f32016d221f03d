"""The 400 Hz batch kernel against the per-sample path it replaces (MEKF predict + star
projection per sample, flags by hand), and the block-wise predict against the 6×6 one."""

import math

import numpy as np
import pytest
from gyrostar.core.mekf import mekf_predict
from gyrostar.gyro.convert import FLAG_GAP, FLAG_SAT_Y, FLAG_STUCK_AXIS
from gyrostar.loop import record as R
from gyrostar.loop.attitude_filter import AttitudeFilter
from gyrostar.loop.kernels import project_refs


def test_batch_matches_per_sample_predict_and_projection():
    rng = np.random.default_rng(3)
    cam = np.array([6666.6, 511.5, 511.5, 0, 0, 0, 0, 0, 1024, 1024])
    refs = rng.normal(size=(5, 3)) * 0.02 + np.array([0, 0, 1.0])
    refs /= np.linalg.norm(refs, axis=1)[:, None]
    ids = np.arange(100, 105, dtype=np.int32)
    n = 7
    t = 10.0 + np.arange(n) * 0.0025
    t[4:] += 0.0025                                  # a late sample: its own dt
    rate = rng.normal(size=(n, 3)) * 0.01
    flags = np.zeros(n, np.uint8)
    flags[2] = FLAG_GAP
    flags[3] = FLAG_SAT_Y
    flags[5] = FLAG_STUCK_AXIS

    f = AttitudeFilter(1.7e-4, 1e-6, 0.02, 0.0025)
    f.ts[0] = 10.0 - 0.0025
    q, b, P = f.q.copy(), f.b.copy(), f.P.copy()
    out = R.empty(n)
    uv_track = np.full((R.MAX_STARS, 2), -7.0)
    slots = np.array([1, 3, 4, 6, 9])     # the stars' track slots: their rows of uv_track are written

    class Smp:
        pass
    smp = Smp()
    smp.t, smp.rate, smp.flags, smp.n = t, rate, flags, n
    stuck = f.predict(smp, R.FLAG_OVERRUN, R.FLAG_ATTITUDE_VALID, R.MODE_TRACK, refs, ids, cam, slots, uv_track, out)
    assert stuck == 1
    t_prev = 10.0 - 0.0025
    for i in range(n):
        mekf_predict(q, b, P, rate[i], t[i] - t_prev, 1.7e-4, 1e-6)
        t_prev = t[i]
        np.testing.assert_allclose(out["q"][i], q, rtol=0, atol=1e-15)
        np.testing.assert_allclose(out["cov"][i], P, rtol=0, atol=1e-14 * abs(P).max())   # by blocks: other order
        np.testing.assert_allclose(out["omega"][i], rate[i] - b, rtol=0, atol=1e-15)
        uv, _ = project_refs(cam, q, refs)
        np.testing.assert_allclose(out["centroid_px"][i][:5], uv, rtol=0, atol=1e-3)   # f4 field
        assert list(out["star_id"][i][:5]) == list(ids) and out["n_stars"][i] == 5
        assert out["seq"][i] == i and out["mode"][i] == R.MODE_TRACK
    np.testing.assert_allclose(f.q, q, rtol=0, atol=1e-15)
    np.testing.assert_allclose(uv_track[slots], uv, rtol=0, atol=1e-9)
    others = np.setdiff1d(np.arange(R.MAX_STARS), slots)
    assert np.all(uv_track[others] == -7.0)
    fl = out["flags"]
    assert all(x & R.FLAG_ATTITUDE_VALID for x in fl)
    assert [bool(x & R.FLAG_OVERRUN) for x in fl] == [True] + [False] * (n - 1)
    assert [i for i in range(n) if fl[i] & R.FLAG_GYRO_GAP] == [2]
    assert [i for i in range(n) if fl[i] & R.FLAG_GYRO_SATURATED] == [3]
    assert [i for i in range(n) if fl[i] & R.FLAG_GYRO_STUCK] == [5]
    # history: the attitude at a sample time is the output at that sample
    np.testing.assert_allclose(f.q_at(t[3]), out["q"][3], atol=1e-15)
    assert math.isclose(f.t_last, t[-1])


def test_batch_without_stars_writes_no_centroids():
    f = AttitudeFilter(1.7e-4, 1e-6, 0.02, 0.0025)
    out = R.empty(2)
    uv_track = np.full((R.MAX_STARS, 2), 5.0)

    class Smp:
        t = np.array([1.0, 1.0025])
        rate = np.zeros((2, 3))
        flags = np.zeros(2, np.uint8)
        n = 2
    f.predict(Smp, 0, 0, R.MODE_ACQUIRE, np.zeros((0, 3)), np.zeros(0, np.int32),
              np.array([6666.6, 511.5, 511.5, 0, 0, 0, 0, 0, 1024, 1024]), np.zeros(0, np.int64), uv_track, out)
    assert list(out["n_stars"]) == [0, 0] and (out["star_id"] == -1).all()
    assert np.all(uv_track == 5.0)          # no tracked star: the tracks' table is left alone
    assert list(out["seq"]) == [0, 1]


def test_block_predict_matches_the_full_predict():
    from gyrostar.core.mekf import mekf_init, mekf_predict_blocks

    rng = np.random.default_rng(1)
    for scale in (1e-9, 0.1, 1.0):          # the small-angle branch and large rotations
        q, b, P = mekf_init(np.array([0.1, 0.2, 0.3, 0.9]), rng.normal(size=3) * 1e-3, 1e-3, 1e-2)
        a = rng.normal(size=(6, 6)) * 1e-3
        P += a @ a.T
        q2, b2, P2 = q.copy(), b.copy(), P.copy()
        E, T = np.zeros((3, 3)), np.zeros((3, 3))
        for _ in range(50):
            w = rng.normal(size=3) * scale
            mekf_predict(q, b, P, w, 0.0025, 1.7e-4, 1e-6)
            mekf_predict_blocks(q2, b2, P2, w, 0.0025, 1.7e-4, 1e-6, E, T)
        np.testing.assert_allclose(P2, P, rtol=0, atol=1e-14 * np.abs(P).max())
        np.testing.assert_allclose(q2, q, rtol=0, atol=1e-15)


def test_gyro_delay_shifts_the_history_and_carries_outputs_on():
    from gyrostar.attitude import quat_propagate

    tau = 0.0048
    f = AttitudeFilter(1.7e-4, 1e-6, 0.02, 0.0025, delay_s=tau)
    out = R.empty(3)

    class Smp:
        t = np.array([1.0, 1.0025, 1.005])
        rate = np.tile([0.01, -0.02, 0.03], (3, 1))
        flags = np.zeros(3, np.uint8)
        n = 3
    f.predict(Smp, 0, 0, R.MODE_TRACK, np.zeros((0, 3)), np.zeros(0, np.int32),
              np.array([6666.6, 511.5, 511.5, 0, 0, 0, 0, 0, 1024, 1024]), np.zeros(0, np.int64),
              np.zeros((R.MAX_STARS, 2)), out)
    assert list(out["t"]) == list(Smp.t)                       # stamps unchanged
    assert f.t_last == pytest.approx(1.005 - tau)              # the filter runs on t − τ
    np.testing.assert_allclose(out["q"][2], quat_propagate(f.q, f.omega, tau), atol=1e-12)
    np.testing.assert_allclose(f.q_at(1.005 - tau), f.q, atol=1e-15)


def test_rate_proportional_error_grows_linearly_from_the_last_fix():
    """A scale/misalignment error σ_s is constant: at rate ω the attitude error it adds since
    the last fix at t_f is σ_s ω (t − t_f), so a coast's variance is σ_v² T + (σ_s ω T)²
    (the steps' increments σ_s² ω² (2a + dt) dt sum to it exactly), and a filter fixed 10 ms
    ago carries (σ_s ω · 10 ms)², not a walk at the coast's slope."""
    sv, ss, w = 1.7e-4, 0.005, 0.6                      # rad/√s, rad/rad, rad/s (34 °/s)
    cam = np.array([6666.6, 511.5, 511.5, 0, 0, 0, 0, 0, 1024, 1024])

    def coast(n):
        f = AttitudeFilter(sv, 0.0, 0.0, 0.0025, rate_error=ss)
        f.P[:] = 0.0
        f.ts[0] = 20.0
        f.ts[4] = 20.0                                  # the last fix
        smp = type("Smp", (), {})()
        smp.t = 20.0 + np.arange(1, n + 1) * 0.0025
        smp.rate, smp.flags, smp.n = np.tile([0.0, 0.0, w], (n, 1)), np.zeros(n, np.uint8), n
        f.predict(smp, 0, 0, R.MODE_COAST, np.zeros((0, 3)), np.zeros(0, np.int32), cam, np.zeros(0, np.int64),
                  np.zeros((R.MAX_STARS, 2)), R.empty(n))
        return np.diag(f.P[:3, :3])

    for n in (4, 400, 2000):                            # 10 ms, 1 s, 5 s
        T = n * 0.0025
        np.testing.assert_allclose(coast(n), sv ** 2 * T + (ss * w * T) ** 2, rtol=1e-9)
    # 10 ms after a fix the scale error holds 0.6 % of what a 5 s walk at its slope would
    assert coast(4)[0] - sv ** 2 * 0.01 < 0.01 * ss ** 2 * w ** 2 * 5.0 * 0.01
