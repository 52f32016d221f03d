"""Quaternion conventions against hand-computed vectors."""

import numpy as np
from gyrostar import attitude as att


def test_dcm_of_rotation_about_z_hand_vector():
    # 90 deg about +z: q = [0, 0, sin45, cos45]; frame rotation maps inertial x to body -y
    q = np.array([0.0, 0.0, np.sqrt(0.5), np.sqrt(0.5)])
    a = att.quat_to_dcm(q)
    np.testing.assert_allclose(a @ np.array([1.0, 0, 0]), [0, -1, 0], atol=1e-12)
    np.testing.assert_allclose(a @ np.array([0, 1.0, 0]), [1, 0, 0], atol=1e-12)


def test_composition_matches_matrix_product():
    rng = np.random.default_rng(3)
    q, p = att.random_attitudes(2, rng)
    np.testing.assert_allclose(att.quat_to_dcm(att.quat_mult(q, p)),
                               att.quat_to_dcm(q) @ att.quat_to_dcm(p), atol=1e-12)


def test_dcm_quat_round_trip_all_branches():
    rng = np.random.default_rng(4)
    for q in att.random_attitudes(200, rng):
        np.testing.assert_allclose(att.dcm_to_quat(att.quat_to_dcm(q)), att.quat_normalize(q), atol=1e-10)
    for q in ([1.0, 0, 0, 0], [0, 1.0, 0, 0], [0, 0, 1.0, 0]):  # 180-degree rotations
        q = np.array(q)
        np.testing.assert_allclose(att.quat_to_dcm(att.dcm_to_quat(att.quat_to_dcm(q))),
                                   att.quat_to_dcm(q), atol=1e-12)


def test_propagation_moves_stars_as_minus_omega_cross_s():
    q0 = att.quat_from_boresight(0.3, -0.2, 0.1)
    s_i = att.radec_to_vec(0.31, -0.19)
    omega = np.array([0.01, -0.02, 0.03])
    dt = 1e-4
    s0 = att.quat_rotate(q0, s_i)
    s1 = att.quat_rotate(att.quat_propagate(q0, omega, dt), s_i)
    np.testing.assert_allclose((s1 - s0) / dt, -np.cross(omega, s0), atol=1e-7)


def test_boresight_and_north_up():
    ra, dec = np.radians(40.0), np.radians(20.0)
    q = att.quat_from_boresight(ra, dec, 0.0)
    np.testing.assert_allclose(att.quat_rotate(q, att.radec_to_vec(ra, dec)), [0, 0, 1], atol=1e-12)
    # a star slightly north appears at negative y (image up)
    north = att.quat_rotate(q, att.radec_to_vec(ra, dec + 0.01))
    assert north[1] < 0 and abs(north[0]) < 1e-12


def test_error_angles_small_rotation():
    q = att.quat_from_boresight(1.0, 0.5, 0.2)
    dtheta = np.array([1e-5, -2e-5, 3e-5])
    q_est = att.quat_mult(att.rotvec_to_quat(dtheta), q)
    np.testing.assert_allclose(att.quat_error_angles(q_est, q), dtheta, atol=1e-12)


def test_constant_rate_integration_is_exact():
    q0 = att.quat_from_boresight(0.0, 0.0, 0.0)
    omega = np.radians([3.0, -2.0, 5.0])
    q = q0.copy()
    for _ in range(1000):
        q = att.quat_propagate(q, omega, 1e-3)
    np.testing.assert_allclose(q, att.quat_propagate(q0, omega, 1.0), atol=1e-12)
