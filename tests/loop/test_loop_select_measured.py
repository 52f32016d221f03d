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


def test_plan_tracked_equals_its_parts():
    """The tracked slots brightest first (ties in slot order), projected, moved on by the held
    rate over the lag (5.3 ms: not a whole number of 2.5 ms gyro samples), through
    plan_windows: the one-call plan gives the same arrays as the parts called one by one."""
    from gyrostar.core.motion import predict_trajectory, substeps_for
    from gyrostar.loop.image_kernels import plan_tracked, plan_windows
    from gyrostar.loop.kernels import project_refs

    rng = np.random.default_rng(5)
    cam = np.array([6640.0, 511.5, 507.5, 0, 0, 0, 0, 0, 1024, 1024])
    q = quat_from_boresight(0.7, -0.3, 0.5)
    a = quat_to_dcm(q)
    S = 20
    ref = rng.standard_normal((S, 3)) * 0.03 + a[2]
    ref /= np.linalg.norm(ref, axis=1)[:, None]
    active = rng.random(S) < 0.7
    nav = rng.permutation(40)[:S].astype(np.int64)
    vmag = np.round(rng.uniform(2.0, 6.0, 40), 1)            # rounded: equal magnitudes occur
    omega, bias = np.radians([0.4, -0.2, 0.1]), np.radians([0.01, 0.0, -0.02])
    m, lag, dt = 4, 0.0053, 0.0025
    got = plan_tracked(active, nav, vmag, ref, q, omega, bias, m, lag, dt, cam, 1, 8, 1024, 1024, 4000, 2048, 400)
    act = np.flatnonzero(active)
    order = act[np.argsort(vmag[nav[act]], kind="stable")]
    uv, _ = project_refs(cam, q, ref[order])
    rates = np.repeat((omega + bias)[None, :], m, axis=0)
    sub_lag = substeps_for(rates[:1] - bias, lag, cam[0], 0.5)
    for j in range(len(uv)):
        end = predict_trajectory(uv[j, 0] - cam[1], uv[j, 1] - cam[2], rates[:1], lag, bias, cam[0], 1, sub_lag)[-1]
        uv[j] = end + cam[1:3]
    sub = substeps_for(rates - bias, dt, cam[0], 0.5)
    want = plan_windows(uv, order.astype(np.int64), rates, dt, bias, cam, 1, sub, 0, 8, 1024, 1024, 4000, 2048, 400)
    for g, w in zip(got[:5], want):
        assert np.array_equal(g, w)
    assert np.array_equal(got[5], nav[want[1]]) and len(want[1]) >= 5
    assert len(set(vmag[nav[act]])) < len(act)              # the field had ties to order


def test_plan_moves_the_stars_over_the_exact_lag():
    """At 10 °/s a gyro sample (2.5 ms) is 2.9 px of star motion: the plan must move the stars
    over the lag to the exposure start as it is (6.2 ms), not rounded to whole samples (5 ms,
    1.4 px short). Truth: the same plan with no lag from the attitude rotated exactly over
    6.2 ms (attitude.quat_propagate) gives the same windows."""
    from gyrostar.attitude import quat_propagate
    from gyrostar.loop.image_kernels import plan_tracked

    rng = np.random.default_rng(7)
    cam = np.array([6666.67, 511.5, 511.5, 0, 0, 0, 0, 0, 1024, 1024])
    q = quat_from_boresight(1.1, 0.4, 0.2)
    a = quat_to_dcm(q)
    S = 10
    ref = rng.standard_normal((S, 3)) * 0.02 + a[2]
    ref /= np.linalg.norm(ref, axis=1)[:, None]
    active, nav, vmag = np.ones(S, np.bool_), np.arange(S, dtype=np.int64), np.linspace(3.0, 6.0, S)
    omega, bias = np.radians([6.0, 8.0, 0.0]), np.zeros(3)
    m, dt, lag = 4, 0.0025, 0.0062
    got = plan_tracked(active, nav, vmag, ref, q, omega, bias, m, lag, dt, cam, 1, 6, 1024, 1024, 8192, 2048, 512)
    truth = plan_tracked(active, nav, vmag, ref, quat_propagate(q, omega, lag), omega, bias, m, 0.0, dt, cam, 1, 6,
                         1024, 1024, 8192, 2048, 512)
    rounded = plan_tracked(active, nav, vmag, ref, quat_propagate(q, omega, 0.005), omega, bias, m, 0.0, dt, cam, 1,
                           6, 1024, 1024, 8192, 2048, 512)
    assert np.array_equal(got[1], truth[1]) and len(got[1]) >= 8
    # window by window: the same rows and columns within a pixel (a square's edge may round
    # the other way), and far from the plan a whole-sample lag gives
    def box(spans, w):
        s = spans[spans[:, 0] == w]
        return np.array([s[:, 1].min(), s[:, 1].max(), s[:, 2].min(), s[:, 3].max()])

    for w in got[1]:
        assert np.abs(box(got[0], w) - box(truth[0], w)).max() <= 1
    assert max(np.abs(box(rounded[0], w) - box(truth[0], w)).max() for w in truth[1]) >= 1


def test_score_slots_restarts_the_accepted_and_names_the_fifth_rejection():
    """Hand-counted: slot 2 accepted (its counts restart), slots 5 and 7 rejected; slot 7's
    rejection is its fifth in a row, slot 5's its second."""
    from gyrostar.loop.image_kernels import score_slots

    misses = np.array([0, 0, 3, 0, 0, 1, 0, 2], np.int64)
    rejects = np.array([0, 0, 2, 0, 0, 1, 0, 4], np.int64)
    wrong = score_slots(np.array([2, 5, 7], np.int64), np.array([True, False, False]), misses, rejects, 5)
    assert wrong.tolist() == [7]
    assert misses.tolist() == [0, 0, 0, 0, 0, 1, 0, 2]          # only an accepted star's misses restart
    assert rejects.tolist() == [0, 0, 0, 0, 0, 2, 0, 5]


def test_apply_frame_equals_its_parts():
    """One frame through ``frame_kernel.apply_frame`` and through its parts called one by one
    (select_measured, consistent, AttitudeFilter.update on the consistent stars, score_slots):
    the same filter state to the bit, the same track counts, the same counts. The frame: 7
    windows, one missed, one whose slot now tracks another star, one centroid 140″ off (the
    consistency check drops it)."""
    from gyrostar.attitude import quat_mult, rotvec_to_quat
    from gyrostar.loop import record as R
    from gyrostar.loop.attitude_filter import GATE, QD_MARGIN, SMOOTH_GAP_S, AttitudeFilter
    from gyrostar.loop.frame_kernel import N_ACCEPTED, N_CONSISTENT, N_MEASURED, N_USED, apply_frame
    from gyrostar.loop.image_kernels import score_slots

    rng = np.random.default_rng(11)
    S = R.MAX_STARS
    q_true = quat_from_boresight(0.9, 0.3, 0.1)
    a = quat_to_dcm(q_true)
    refs = rng.standard_normal((S, 3)) * 0.04 + a[2]
    refs /= np.linalg.norm(refs, axis=1)[:, None]
    filters = []
    # 7.7″ off truth: the boresight 4.6″, the rest roll
    q_start = quat_mult(rotvec_to_quat(np.array([2e-5, -1e-5, 3e-5])), q_true)
    for _ in range(2):
        f = AttitudeFilter(1.7e-4 / math.sqrt(2), 1e-6, 0.02, 0.0025)
        f.q[:] = q_start
        f.P[:3, :3] = np.eye(3) * (2e-5) ** 2
        f.valid = True
        smp = type("Smp", (), {})()
        smp.t = 10.0 + np.arange(1, 41) * 0.0025
        smp.rate, smp.flags, smp.n = np.zeros((40, 3)), np.zeros(40, np.uint8), 40
        f.predict(smp, 0, 0, R.MODE_TRACK, np.zeros((0, 3)), np.zeros(0, np.int32), np.zeros(10),
                  np.zeros(0, np.int64), np.zeros((S, 2)), R.empty(40))
        filters.append(f)
    wins = np.array([0, 1, 2, 3, 4, 5, 6], np.int64)
    planned = np.arange(7, dtype=np.int64) + 100
    nav = np.arange(S, dtype=np.int64) + 100
    nav[5] = 555                                               # slot 5 refilled since the plan
    active = np.zeros(S, np.bool_)
    active[:7] = True
    state = np.full(7, MEAS_OK, np.int8)
    state[3] = MEAS_MISS
    b_mid = refs[:7] @ a.T + rng.standard_normal((7, 3)) * 3e-6
    b_mid[2] += np.array([7e-4, 0.0, 0.0])                     # 140″ off: another star's light
    b_mid /= np.linalg.norm(b_mid, axis=1)[:, None]
    sig = np.full(7, 5e-6)
    t_mid = 10.0 + 30 * 0.0025
    tracks = [(np.zeros(S, np.int64), np.zeros(S, np.int64)) for _ in range(2)]
    tracks[0][1][2] = tracks[1][1][2] = 4                      # slot 2: its fifth rejection now

    f = filters[0]
    misses, rejects = tracks[0]
    counts, info, wrong = apply_frame(wins, planned, state, b_mid, sig, active, nav, misses, rejects, refs, 0.0,
                                      False, 6.0, 1.5 / 6640.0, *f.update_operands, t_mid,
                                      3, GATE, QD_MARGIN, SMOOTH_GAP_S, 5)

    g = filters[1]
    misses2, rejects2 = tracks[1]
    slots, bu, ru, su = select_measured(wins, planned, state, b_mid, sig, active, nav, misses2, refs, 0.0, False)
    ok = consistent(bu, ru, su, 6.0, 1.5 / 6640.0)
    sub = np.zeros(int(ok.sum()), np.uint8)
    used = g.update(t_mid, bu[ok], ru[ok], su[ok], sub, 3)
    acc = np.zeros(len(slots), np.uint8)
    acc[ok] = sub
    good = acc.astype(bool)
    wrong2 = score_slots(slots, good, misses2, rejects2, 5)

    assert slots.tolist() == [0, 1, 2, 4, 6] and ok.tolist() == [True, True, False, True, True]
    assert counts.tolist() == [5, 4, used, int(good.sum())] and used == 4
    assert counts[N_MEASURED] == 5 and counts[N_CONSISTENT] == 4 and counts[N_USED] == counts[N_ACCEPTED] == 4
    assert info == float(np.sum(1.0 / su[good] ** 2)) and wrong.tolist() == wrong2.tolist() == [2]
    for x, y in zip(f.state_arrays + (f.mid, f.smoothed), g.state_arrays + (g.mid, g.smoothed)):
        assert np.array_equal(x, y, equal_nan=True)
    assert np.array_equal(misses, misses2) and np.array_equal(rejects, rejects2) and misses[3] == 1
    # the update took the boresight to truth (roll, about it, 4 close stars see weakly)
    def off(q):
        return math.acos(min(1.0, float(quat_to_dcm(q)[2] @ a[2])))
    assert off(f.q) < 0.2 * off(q_start) and off(f.q) < 1e-5
