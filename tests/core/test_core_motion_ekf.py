"""Spot motion and the spot EKF against the exact projection of a rotating star."""

import numpy as np
import pytest
from gyrostar.attitude import quat_propagate, quat_to_dcm
from gyrostar.core.motion import (
    MODEL_FIRST_ORDER,
    MODEL_PINHOLE,
    predict_trajectory,
    spot_velocity,
    step_spot,
)
from gyrostar.core.spot_ekf import (
    CHI2_2DOF_999,
    spot_ekf_init,
    spot_ekf_predict,
    spot_ekf_propagate,
    spot_ekf_reset,
    spot_ekf_update,
    transition,
)

F_PX = 100e-3 / 15e-6  # xing2012: F = 100 mm, 15 µm pixels


def project_truth(q, s_icrs):
    """Exact pinhole projection (px from the principal point) of an ICRS direction."""
    b = quat_to_dcm(q) @ s_icrs
    return F_PX * b[0] / b[2], F_PX * b[1] / b[2]


def star_at(x, y):
    s = np.array([x, y, F_PX])
    return s / np.linalg.norm(s)  # ICRS = body at the identity attitude


@pytest.mark.parametrize("xy", [(0.0, 0.0), (300.0, -200.0), (-480.0, 450.0)])
def test_velocity_matches_exact_projection(xy):
    omega = np.radians([3.0, -4.0, 5.0])
    s = star_at(*xy)
    q0 = np.array([0.0, 0.0, 0.0, 1.0])
    h = 1e-6
    xp = np.array(project_truth(quat_propagate(q0, omega, h), s))
    xm = np.array(project_truth(quat_propagate(q0, omega, -h), s))
    v_true = (xp - xm) / (2 * h)
    v_full = np.array(spot_velocity(xy[0], xy[1], omega, F_PX, MODEL_PINHOLE))
    v_lin = np.array(spot_velocity(xy[0], xy[1], omega, F_PX, MODEL_FIRST_ORDER))
    np.testing.assert_allclose(v_full, v_true, rtol=1e-6, atol=1e-6)
    # sign/axis check of the paper's eq. 2.1 in our frame: V_x = ω_z y − ω_y f, V_y = −ω_z x + ω_x f
    np.testing.assert_allclose(v_lin, [omega[2] * xy[1] - omega[1] * F_PX, -omega[2] * xy[0] + omega[0] * F_PX])
    r = np.hypot(*xy)
    # first order is off by the off-axis terms only (~ r²/f² of the rate term)
    assert np.linalg.norm(v_lin - v_true) <= 2.0 * (r / F_PX) ** 2 * np.linalg.norm(omega) * F_PX + 1e-6


def test_trajectory_matches_truth_over_an_exposure():
    omega = np.radians([5.0, 5.0, 5.0])
    s = star_at(400.0, -350.0)
    dt = 1 / 400
    rates = np.tile(omega, (4, 1))
    traj = predict_trajectory(400.0, -350.0, rates, dt, np.zeros(3), F_PX, MODEL_PINHOLE, 3)
    q = np.array([0.0, 0.0, 0.0, 1.0])
    for k in range(1, traj.shape[0]):
        qt = quat_propagate(q, omega, k * dt / 3)
        np.testing.assert_allclose(traj[k], project_truth(qt, s), atol=1e-8)
    lin = predict_trajectory(400.0, -350.0, rates, dt, np.zeros(3), F_PX, MODEL_FIRST_ORDER, 3)
    err = np.abs(lin[-1] - traj[-1]).max()
    assert 1e-3 < err < 0.2  # the off-axis terms matter at the 0.01-px level here


@pytest.mark.parametrize("model", [MODEL_FIRST_ORDER, MODEL_PINHOLE])
def test_transition_is_the_jacobian(model):
    """Φ equals the finite-difference Jacobian of the propagation (first-order accurate in Δt)."""
    X0 = np.array([250.0, -120.0, 1e-3, -2e-3, 5e-4])
    omega = np.radians([2.0, -3.0, 4.0])
    dt = 1 / 400

    def prop(X):
        x, y = step_spot(X[0], X[1], *(omega - X[2:]), dt, F_PX, model)
        return np.array([x, y, *X[2:]])

    jac = np.empty((5, 5))
    for j in range(5):
        e = np.zeros(5)
        e[j] = 1e-3 if j < 2 else 1e-7
        jac[:, j] = (prop(X0 + e) - prop(X0 - e)) / (2 * e[j])
    phi, psi, _ = transition(X0, omega, dt, F_PX, model)
    if model == MODEL_FIRST_ORDER:
        # paper's Φ uses ω_mea (not ω_mea − b) for the roll coupling: differs by b_z·Δt
        np.testing.assert_allclose(phi[:2, 2:], jac[:2, 2:], rtol=1e-6)
        np.testing.assert_allclose(phi[:2, :2], jac[:2, :2], atol=abs(X0[4]) * dt * 1.01)
        np.testing.assert_allclose(phi @ X0 + psi, prop(X0), atol=1e-9)  # eq. 3.4 holds exactly
    else:
        # Φ = I + J·Δt is first order: it differs from the exact step by O(f·|ω|·Δt²)
        second_order = F_PX * np.linalg.norm(omega) * dt * dt
        np.testing.assert_allclose(phi, jac, atol=second_order, rtol=1e-3)


def test_ekf_tracks_and_estimates_bias_from_truth():
    """Static star, gyro with drift + white noise, noisy centroids: drift and position converge."""
    rng = np.random.default_rng(3)
    dt = 1 / 400
    bias = np.radians([0.02, -0.02, 0.02])
    omega = np.radians([0.5, -0.3, 0.2])
    s = star_at(200.0, 100.0)
    sig_rate = np.radians(0.05)
    sig_meas = 0.1
    X, P = spot_ekf_init(200.0, 100.0, np.zeros(3), 0.5, np.radians(0.1))
    q = np.array([0.0, 0.0, 0.0, 1.0])
    errs = []
    for k in range(1, 3201):  # 8 s
        q = quat_propagate(q, omega, dt)
        w_meas = omega + bias + rng.standard_normal(3) * sig_rate
        spot_ekf_predict(X, P, w_meas, dt, F_PX, sig_rate, 1e-7, MODEL_PINHOLE)
        if k % 4 == 0:
            zx, zy = np.array(project_truth(q, s)) + rng.standard_normal(2) * sig_meas
            ok, nis = spot_ekf_update(X, P, zx, zy, sig_meas ** 2, sig_meas ** 2, CHI2_2DOF_999)
            assert ok
            errs.append(X[:2] - project_truth(q, s))
    errs = np.array(errs[200:])
    assert np.sqrt((errs ** 2).mean(axis=0)).max() < 0.8 * sig_meas
    # b_x and b_y are observable through the large f terms; b_z only through the roll lever arm
    assert abs(X[2] - bias[0]) < 0.1 * abs(bias[0])
    assert abs(X[3] - bias[1]) < 0.1 * abs(bias[1])
    # covariance is consistent with the actual errors
    assert np.sqrt(P[0, 0]) == pytest.approx(np.sqrt((errs[:, 0] ** 2).mean()), rel=0.5)


def test_gate_rejects_outlier_and_reset_reacquires():
    X, P = spot_ekf_init(0.0, 0.0, np.zeros(3), 0.1, 1e-3)
    bias_before = X[2:].copy()
    ok, nis = spot_ekf_update(X, P, 5.0, 0.0, 0.01, 0.01, CHI2_2DOF_999)
    assert not ok and nis > CHI2_2DOF_999 and X[0] == 0.0
    ok, _ = spot_ekf_update(X, P, np.nan, 0.0, 0.01, 0.01, CHI2_2DOF_999)
    assert not ok
    spot_ekf_reset(X, P, 5.0, 1.0, 0.01, 0.01)
    assert X[0] == 5.0 and X[1] == 1.0 and np.all(X[2:] == bias_before)
    assert P[0, 0] == 0.01 and P[0, 2] == 0.0
    spot_ekf_propagate(X, P, np.zeros((4, 3)), 1 / 400, F_PX, 1e-3, 1e-7, MODEL_FIRST_ORDER)
    assert P[0, 0] > 0.01  # uncertainty grows between images


def test_delayed_update_equals_update_at_mid_exposure():
    from gyrostar.core.spot_ekf import spot_ekf_update_delayed

    rng = np.random.default_rng(8)
    rates = rng.normal(0, 0.05, (4, 3))
    X, P = spot_ekf_init(120.0, -80.0, np.zeros(3), 0.2, 1e-3)
    args = (1 / 400, F_PX, 1e-3, 1e-7, MODEL_PINHOLE)
    spot_ekf_propagate(X, P, rates[:2], *args)
    Xa, Pa = X.copy(), P.copy()  # reference: update at mid, then propagate
    spot_ekf_update(Xa, Pa, X[0] + 0.1, X[1] - 0.1, 0.01, 0.01, CHI2_2DOF_999)
    spot_ekf_propagate(Xa, Pa, rates[2:], *args)
    X_mid, P_mid = X.copy(), P.copy()  # loop: keep predicting, image arrives later
    spot_ekf_propagate(X, P, rates[2:], *args)
    ok, _ = spot_ekf_update_delayed(X, P, X_mid, P_mid, X_mid[0] + 0.1, X_mid[1] - 0.1, 0.01, 0.01,
                                    CHI2_2DOF_999, rates[2:], *args)
    assert ok
    np.testing.assert_allclose(X, Xa, rtol=0, atol=1e-12)
    np.testing.assert_allclose(P, Pa, rtol=1e-12, atol=1e-18)
