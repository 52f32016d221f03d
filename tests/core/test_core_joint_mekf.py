"""Joint spot filter and attitude MEKF against simulated truth."""

import numpy as np
import pytest
from gyrostar.attitude import quat_error_angles, quat_propagate, quat_to_dcm
from gyrostar.core.joint_filter import joint_add_star, joint_init, joint_predict, joint_update, joint_workspace
from gyrostar.core.mekf import mekf_init, mekf_predict, mekf_update
from gyrostar.core.motion import MODEL_PINHOLE
from gyrostar.core.spot_ekf import CHI2_2DOF_999, spot_ekf_init, spot_ekf_predict, spot_ekf_update

F_PX = 100e-3 / 15e-6
DT = 1 / 400


def project(q, s):
    b = quat_to_dcm(q) @ s
    return np.array([F_PX * b[0] / b[2], F_PX * b[1] / b[2]])


def make_stars(rng, n):
    xy = rng.uniform(-450, 450, (n, 2))
    s = np.column_stack([xy, np.full(n, F_PX)])
    return xy, s / np.linalg.norm(s, axis=1)[:, None]


def test_joint_filter_with_one_star_equals_spot_ekf():
    rng = np.random.default_rng(0)
    X1, P1 = spot_ekf_init(100.0, -50.0, np.zeros(3), 0.3, 1e-3)
    X, P, act = joint_init(3, np.zeros(3), 1e-3)
    joint_add_star(X, P, act, 1, 100.0, -50.0, 0.09)
    work = joint_workspace(3)
    z = np.full((3, 2), np.nan)
    rv = np.full((3, 2), 0.01)
    acc = np.zeros(3, np.uint8)
    nis = np.zeros(3)
    for k in range(40):
        w = rng.normal(0, 0.01, 3)
        spot_ekf_predict(X1, P1, w, DT, F_PX, 1e-3, 1e-6, MODEL_PINHOLE)
        joint_predict(X, P, act, w, DT, F_PX, 1e-3, 1e-6, MODEL_PINHOLE, work)
        if k % 4 == 3:
            zz = X1[:2] + rng.normal(0, 0.1, 2)
            spot_ekf_update(X1, P1, zz[0], zz[1], 0.01, 0.01, CHI2_2DOF_999)
            z[1] = zz
            joint_update(X, P, act, z, rv, CHI2_2DOF_999, acc, nis)
            assert acc[1] == 1 and acc[0] == 0
    idx = [2, 3, 6, 7, 8]
    np.testing.assert_allclose(X[idx], X1, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(P[np.ix_(idx, idx)], P1, rtol=1e-8, atol=1e-16)
    assert np.all(P[:2] == 0.0)  # unused slot untouched


def test_joint_filter_estimates_bias_better_than_single_star():
    """Ten stars sharing one drift pin it down faster than one star alone (incl. b_z via roll)."""
    rng = np.random.default_rng(5)
    n = 10
    xy, s = make_stars(rng, n)
    bias = np.radians([0.02, -0.02, 0.02])
    omega = np.radians([1.0, 0.5, -0.8])
    # per-sample rate noise 0.02 °/s (ND 0.001 °/s/√Hz): the drift cannot be known better
    # than ND/√T from any number of stars, so the noise must be small for a 10 % check at 3 s
    sig_rate = np.radians(0.02)
    X, P, act = joint_init(n, np.zeros(3), np.radians(0.1))
    X1, P1 = spot_ekf_init(xy[0, 0], xy[0, 1], np.zeros(3), 0.1, np.radians(0.1))
    for i in range(n):
        joint_add_star(X, P, act, i, xy[i, 0], xy[i, 1], 0.01)
    work = joint_workspace(n)
    q = np.array([0.0, 0.0, 0.0, 1.0])
    acc = np.zeros(n, np.uint8)
    nis = np.zeros(n)
    rv = np.full((n, 2), 0.01)
    n_acc = 0
    nis_all = []
    for k in range(1, 1201):  # 3 s
        q = quat_propagate(q, omega, DT)
        w = omega + bias + rng.normal(0, sig_rate, 3)
        joint_predict(X, P, act, w, DT, F_PX, sig_rate, 1e-7, MODEL_PINHOLE, work)
        spot_ekf_predict(X1, P1, w, DT, F_PX, sig_rate, 1e-7, MODEL_PINHOLE)
        if k % 4 == 0:
            z = np.array([project(q, si) for si in s]) + rng.normal(0, 0.1, (n, 2))
            n_acc += joint_update(X, P, act, z, rv, CHI2_2DOF_999, acc, nis)
            nis_all.extend(nis)
            spot_ekf_update(X1, P1, z[0, 0], z[0, 1], 0.01, 0.01, CHI2_2DOF_999)
    assert n_acc >= 0.99 * 300 * n  # the 99.9 % gate rejects ~0.1 % of honest measurements
    assert np.mean(nis_all) == pytest.approx(2.0, rel=0.25)  # NIS ~ χ²₂: consistent filter
    err_joint = np.abs(X[-3:] - bias)
    err_one = np.abs(X1[2:] - bias)
    assert np.all(err_joint[:2] < 0.1 * np.abs(bias[:2]))
    # b_z (roll) is seen only through the off-axis lever arm: slower, but the joint
    # filter knows it better than one star does, and its error is within its 3σ
    assert np.all(err_joint < 3.0 * np.sqrt(np.diag(P)[-3:]))
    assert np.all(err_one < 3.0 * np.sqrt(np.diag(P1)[2:]))
    assert np.sqrt(P[-1, -1]) < 0.5 * np.sqrt(P1[4, 4])
    truth = np.array([project(q, si) for si in s])
    pos_err = X[:2 * n].reshape(n, 2) - truth
    assert np.sqrt((pos_err ** 2).mean()) < 0.1


def test_mekf_converges_and_is_consistent():
    rng = np.random.default_rng(11)
    n = 6
    q_true = np.array([0.1, -0.3, 0.2, 0.9])
    q_true /= np.linalg.norm(q_true)
    stars_body0 = rng.normal(0, 0.05, (n, 3))
    stars_body0[:, 2] = 1.0
    stars_body0 /= np.linalg.norm(stars_body0, axis=1)[:, None]
    refs = stars_body0 @ quat_to_dcm(q_true)  # ICRS vectors of stars in the field at t = 0
    bias = np.radians([0.02, -0.01, 0.03])
    omega = np.radians([0.5, -0.2, 0.3])
    sig_v = np.radians(0.014)  # BMI088 class noise density (°/s/√Hz)
    sig_meas = 5e-5  # rad (~0.33 px at f = 6667 px)
    q_est = quat_propagate(q_true, np.array([0.002, -0.003, 0.004]), 1.0)  # ~0.3° off
    q, b, P = mekf_init(q_est, np.zeros(3), 0.01, np.radians(0.1))
    acc = np.zeros(n, np.uint8)
    nees = []
    for k in range(1, 2401):  # 6 s
        q_true = quat_propagate(q_true, omega, DT)
        w = omega + bias + rng.normal(0, sig_v / np.sqrt(DT), 3)
        mekf_predict(q, b, P, w, DT, sig_v, 1e-7)
        if k % 4 == 0:
            body = refs @ quat_to_dcm(q_true).T + rng.normal(0, sig_meas, (n, 3))
            mekf_update(q, b, P, body, refs, np.full(n, sig_meas), 30.0, acc)
            if k > 1200:
                e = -quat_error_angles(q, q_true)  # a: q_true = δq(a) ⊗ q_est
                nees.append(e @ np.linalg.solve(P[:3, :3], e))
    assert np.linalg.norm(quat_error_angles(q, q_true)) < 5 * sig_meas
    assert np.all(np.abs(b - bias) < 0.1 * np.abs(bias).max())
    assert np.mean(nees) == pytest.approx(3.0, rel=0.5)  # χ²₃ on average: covariance is honest


def _dense_mekf_update(q, b, P, body, refs, sig, gate):
    """Reference: the sequential star update with dense matrices (H 3×6 = [[b̂]×, 0], the
    tangent-plane projection T 2×3, S⁻¹ by numpy, Joseph form), as the textbook writes it."""
    from gyrostar.attitude import quat_mult, quat_normalize, rotvec_to_quat

    q, b, P = q.copy(), b.copy(), P.copy()
    a = quat_to_dcm(q)
    dx = np.zeros(6)
    acc = np.zeros(len(body), np.uint8)
    for i in range(len(body)):
        bh = a @ refs[i]
        bh = bh - np.cross(dx[:3], bh)
        bh /= np.linalg.norm(bh)
        z = body[i] / np.linalg.norm(body[i])
        H = np.zeros((3, 6))
        H[:, :3] = np.array([[0, -bh[2], bh[1]], [bh[2], 0, -bh[0]], [-bh[1], bh[0], 0]])
        t1 = np.cross(bh, [1.0, 0.0, 0.0])
        if t1 @ t1 < 0.1:
            t1 = np.cross(bh, [0.0, 1.0, 0.0])
        t1 /= np.linalg.norm(t1)
        T = np.array([t1, np.cross(bh, t1)])
        H2, y = T @ H, T @ (z - bh)
        S = H2 @ P @ H2.T + sig[i] ** 2 * np.eye(2)
        Si = np.linalg.inv(S)
        if y @ Si @ y > gate:
            continue
        K = P @ H2.T @ Si
        dx += K @ y
        A = np.eye(6) - K @ H2
        P = A @ P @ A.T + sig[i] ** 2 * (K @ K.T)
        acc[i] = 1
    return quat_normalize(quat_mult(rotvec_to_quat(dx[:3]), q)), b + dx[3:], P, acc


def test_mekf_update_equals_the_dense_textbook_update():
    """The written-out star update (no BLAS call per star) against the dense one: equal to
    rounding on random attitudes, covariances, star sets, noise and gates (some stars gated out)."""
    rng = np.random.default_rng(11)
    gated_out = 0
    for _ in range(200):
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)
        L = rng.normal(size=(6, 6))
        P = L @ L.T * 1e-8 + np.eye(6) * 1e-10
        n = int(rng.integers(1, 15))
        refs = rng.normal(size=(n, 3))
        refs /= np.linalg.norm(refs, axis=1)[:, None]
        body = refs @ quat_to_dcm(q).T + rng.normal(size=(n, 3)) * rng.choice([1e-6, 1e-4, 1e-2])
        sig = np.full(n, rng.choice([3e-6, 3e-5]))
        q_ref, b_ref, P_ref, acc_ref = _dense_mekf_update(q, np.zeros(3), P, body, refs, sig, 13.8)
        qq, bb, PP, acc = q.copy(), np.zeros(3), P.copy(), np.zeros(n, np.uint8)
        used = mekf_update(qq, bb, PP, body, refs, sig, 13.8, acc)
        np.testing.assert_array_equal(acc, acc_ref)
        assert used == int(acc_ref.sum())
        gated_out += n - used
        np.testing.assert_allclose(PP, P_ref, rtol=1e-9, atol=1e-22)
        np.testing.assert_allclose(qq, q_ref, atol=1e-12)
        np.testing.assert_allclose(bb, b_ref, atol=1e-15)
    assert gated_out > 0
