"""Attitude truth: exact constant-rate and fixed-axis ramp integration, paper-000 profiles."""

import math

import numpy as np
import pytest
from gyrostar.attitude import quat_error_angles, quat_mult, quat_to_dcm, rotvec_to_quat
from gyrostar.errors import ConfigError
from gyrostar.mocks import trajectory as tj

Q0 = np.array([0.1, -0.2, 0.3, 0.9])
Q0 = Q0 / np.linalg.norm(Q0)


def test_constant_rate_matches_closed_form():
    w = np.radians([3.0, -7.0, 11.0])
    t = np.linspace(0.0, 2.5, 11)
    qs = tj.integrate(Q0, tj.Constant(tuple(w)), t)
    for ti, q in zip(t, qs):
        ref = quat_mult(rotvec_to_quat(w * ti), Q0)
        assert np.abs(quat_error_angles(q, ref)).max() < 1e-12


def test_fixed_axis_ramp_is_exact():
    axis = np.array([1.0, 2.0, -2.0]) / 3.0
    prof = tj.Ramp(tuple(0.0 * axis), tuple(math.radians(8.0) * axis), 0.0, 2.0)
    t = np.array([0.0, 0.7, 2.0, 3.0])
    qs = tj.integrate(Q0, prof, t, max_step_s=0.05)
    a = math.radians(8.0) / 2.0  # angular acceleration, rad/s^2
    for ti, q in zip(t, qs):
        ang = 0.5 * a * min(ti, 2.0) ** 2 + (ti - 2.0) * math.radians(8.0) * (ti > 2.0)
        ref = quat_mult(rotvec_to_quat(axis * ang), Q0)
        assert np.abs(quat_error_angles(q, ref)).max() < 1e-12


def test_star_motion_sign_convention():
    # a star on the boresight under +x body rate moves towards +y (V_y = +w_x F)
    qs = tj.integrate(np.array([0, 0, 0, 1.0]), tj.Constant((0.01, 0.0, 0.0)), np.array([0.0, 1.0]))
    s = quat_to_dcm(qs[1]) @ np.array([0, 0, 1.0])
    assert s[1] > 0 and abs(s[0]) < 1e-12


def test_jitter_and_piecewise_converge():
    prof = tj.Jitter(tj.Piecewise((0.0, 0.5), ((0.01, 0.0, 0.0), (0.0, 0.02, 0.0))),
                     (0.001, 0.002, 0.0), (7.0, 3.0, 1.0))
    t = np.array([0.0, 0.5, 1.0])
    a = tj.integrate(Q0, prof, t, max_step_s=1e-3)
    b = tj.integrate(Q0, prof, t, max_step_s=2.5e-4)
    assert np.abs(quat_error_angles(a[-1], b[-1])).max() < 1e-11


@pytest.mark.parametrize("name,n,first,last", [("sim1", 800, 0.0, 8.0), ("sim2", 300, 0.01, 0.01),
                                               ("sim3", 300, 5.0, 5.0), ("sim4", 500, 5.0, 0.0)])
def test_paper000_profiles(name, n, first, last):
    prof, count = tj.paper000(name)
    assert count == n
    tr = tj.sample(Q0, prof, tj.PAPER000_RATE_HZ, count)
    assert np.degrees(tr.omega[0, 0]) == pytest.approx(first)
    assert np.degrees(tr.omega[-1, 0]) == pytest.approx(last)
    assert tr.q.shape == (n, 4) and np.allclose(np.linalg.norm(tr.q, axis=1), 1.0)


def test_random_attitudes_uniform():
    q = tj.random_attitudes(20000, np.random.default_rng(0))
    bores = np.array([quat_to_dcm(x)[2] for x in q[:5000]])
    assert np.abs(bores.mean(axis=0)).max() < 0.03
    assert np.mean(np.abs(bores[:, 2]) < 0.5) == pytest.approx(0.5, abs=0.03)  # uniform in sin(dec)


def test_bad_inputs():
    with pytest.raises(ConfigError):
        tj.integrate(np.array([0, 0, 0, 2.0]), tj.Constant((0, 0, 0)), np.array([0.0, 1.0]))
    with pytest.raises(ConfigError):
        tj.integrate(Q0, tj.Constant((0, 0, 0)), np.array([1.0, 0.0]))
    with pytest.raises(ConfigError):
        tj.paper000("sim9")


def test_piecewise_attitudes_match_integrator():
    rates = np.radians([[1.0, 2.0, 3.0], [-4.0, 0.5, 2.0], [0.0, 0.0, 9.0], [3.0, 3.0, -3.0]])
    t = np.linspace(0.0, 0.01, 17)
    prof = tj.Piecewise(tuple(np.arange(4) * 0.0025), tuple(map(tuple, rates)))
    grid, inv = np.unique(np.concatenate([t, np.arange(1, 4) * 0.0025]), return_inverse=True)
    ref = tj.integrate(Q0, prof, grid, max_step_s=1.0)[inv[:17]]
    got = tj.piecewise_attitudes(Q0, rates, 0.01, t)
    for a, b in zip(got, ref):
        assert np.abs(quat_error_angles(a, b)).max() < 1e-13


def test_segment_rates_midpoints():
    prof = tj.Ramp((0.0, 0.0, 0.0), (1.0, 2.0, 3.0), 0.0, 1.0)
    r = prof.segment_rates(0.5, 0.01, 4)
    assert r[:, 0] == pytest.approx(0.5 + (np.arange(4) + 0.5) * 0.0025)
    with pytest.raises(ConfigError):
        prof.segment_rates(0.0, 0.01, 0)


def test_integrate_to_is_the_last_row_of_integrate_to_the_bit():
    """The one-interval integrator (the per-frame truth attitude) builds the same grid as
    ``integrate`` and returns its last row bit for bit, on ramps, jitter and piecewise
    profiles, for intervals shorter than, equal to and many times the 1 ms step."""
    rng = np.random.default_rng(4)
    q0 = np.array([0.1, -0.3, 0.2, 0.92])
    q0 /= np.linalg.norm(q0)
    profiles = [tj.Ramp((0.01, 0.02, 0.0), (0.05, -0.01, 0.02), 1.0, 3.0),
                tj.Jitter(tj.Constant((0.0, 0.01, 0.0)), (1e-3, 2e-3, 1e-3), (3.0, 5.0, 7.0)),
                tj.Piecewise((0.0, 0.7, 1.9), ((0.0, 0.0, 0.02), (0.01, 0.0, 0.0), (0.0, -0.03, 0.0))),
                tj.LinearSegments([0.0, 0.8, 2.5], [0.8, 2.5, np.inf],
                                  [(0.0, 0.01, 0.0), (0.02, 0.0, -0.01), (0.0, 0.0, 0.03)],
                                  [(0.02, 0.0, -0.01), (0.0, 0.0, 0.03), (0.0, 0.0, 0.03)])]
    n = 0
    for p in profiles:
        for _ in range(400):
            t0 = rng.uniform(0.0, 4.0)
            gap = rng.choice([rng.uniform(1e-6, 1e-3), 1e-3, 0.0025, 0.01, rng.uniform(0.0, 0.3)])
            if gap <= 0:
                continue
            a = tj.integrate(q0, p, np.array([t0, t0 + gap]))[-1]
            b = tj.integrate_to(q0, p, t0, t0 + gap)
            assert a.tobytes() == b.tobytes(), (p, t0, gap)
            n += 1
    assert n > 1500


def test_linear_segments_rates_by_hand():
    """Linear within each segment, held after the last; a scalar time gives one row."""
    p = tj.LinearSegments([0.0, 2.0], [2.0, np.inf], [(0.0, 0.0, 0.0), (1.0, 1.0, 1.0)],
                          [(2.0, -4.0, 0.0), (1.0, 1.0, 1.0)])
    got = p.rate(np.array([0.0, 0.5, 1.999, 2.0, 7.0, -1.0]))
    want = np.array([[0.0, 0.0, 0.0], [0.5, -1.0, 0.0], [1.999, -3.998, 0.0], [1.0, 1.0, 1.0],
                     [1.0, 1.0, 1.0], [0.0, 0.0, 0.0]])
    assert np.allclose(got, want, rtol=0, atol=1e-15)
    assert p.rate(1.0).shape == (1, 3)
    with pytest.raises(ConfigError):
        tj.LinearSegments([0.0, 1.5], [1.0, 2.0], [(0, 0, 0)] * 2, [(0, 0, 0)] * 2)     # a gap
