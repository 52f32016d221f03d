"""QUEST against hand-computed and simulated truth."""

import numpy as np
import pytest
from gyrostar.attitude import quat_error_angles, quat_to_dcm, random_attitudes, rotvec_to_quat
from gyrostar.core.quest import quest


def test_hand_case_90deg_about_z():
    # q = 90° about z, ICRS -> body: A = Rz(-90°) in the passive sense; x_icrs -> -y_body
    q_true = np.array([0.0, 0.0, np.sin(np.pi / 4), np.cos(np.pi / 4)])
    ref = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    body = np.array([[0.0, -1.0, 0.0], [0.0, 0.0, 1.0]])  # hand-applied A(q) = [[0,1,0],[-1,0,0],[0,0,1]]
    np.testing.assert_allclose(quat_to_dcm(q_true) @ ref[0], body[0], atol=1e-15)
    q, cov = quest(body, ref, np.ones(2))
    assert np.linalg.norm(quat_error_angles(q, q_true)) < 1e-12
    assert np.all(np.isfinite(cov))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_random_attitudes_including_near_180(seed):
    rng = np.random.default_rng(seed)
    qs = random_attitudes(20, rng)
    qs[0] = [1.0, 0.0, 0.0, 0.0]  # exactly 180° about x: plain QUEST is singular here
    qs[1] = rotvec_to_quat(np.array([0.0, np.pi - 1e-7, 0.0]))
    for q_true in qs:
        ref = rng.standard_normal((5, 3))
        ref /= np.linalg.norm(ref, axis=1)[:, None]
        body = ref @ quat_to_dcm(q_true).T
        q, _ = quest(body, ref, np.full(5, 1.0))
        assert np.linalg.norm(quat_error_angles(q, q_true)) < 1e-9


def test_covariance_matches_monte_carlo():
    """Predicted covariance agrees with the scatter of estimates under the QUEST noise model."""
    rng = np.random.default_rng(7)
    q_true = random_attitudes(1, rng)[0]
    a = quat_to_dcm(q_true)
    # a narrow field: 4 stars within ~2° of the boresight (roll poorly observed)
    body0 = np.array([[0.01, 0.02, 1.0], [-0.03, 0.01, 1.0], [0.02, -0.025, 1.0], [-0.01, -0.03, 1.0]])
    body0 /= np.linalg.norm(body0, axis=1)[:, None]
    ref = body0 @ a  # A^T b
    sig = np.array([5e-5, 5e-5, 1e-4, 2e-4])
    w = 1.0 / sig ** 2
    errs = []
    cov = None
    for _ in range(3000):
        noisy = body0.copy()
        for i in range(4):
            n = rng.standard_normal(3) * sig[i]
            n -= (n @ body0[i]) * body0[i]
            noisy[i] = body0[i] + n
            noisy[i] /= np.linalg.norm(noisy[i])
        q, cov = quest(noisy, ref, w)
        errs.append(quat_error_angles(q, q_true))
    errs = np.array(errs)
    emp = np.cov(errs.T)
    for k in range(3):
        assert emp[k, k] == pytest.approx(cov[k, k], rel=0.12)
    # roll about the boresight is far less observable than cross-boresight axes
    assert cov[2, 2] > 50 * cov[0, 0]


def test_single_vector_is_unobservable():
    q, cov = quest(np.array([[0.0, 0.0, 1.0]]), np.array([[0.0, 0.0, 1.0]]), np.ones(1))
    assert not np.all(np.isfinite(cov))


def test_bad_inputs_are_config_errors():
    from gyrostar.errors import ConfigError

    v = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])
    with pytest.raises(ConfigError):
        quest(v, v[:1], np.ones(2))
    with pytest.raises(ConfigError):
        quest(v, v, np.array([1.0, -1.0]))
