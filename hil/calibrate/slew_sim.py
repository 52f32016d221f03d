"""Simulated star-tracker attitudes during a slew, for the calibrations that need them
(``alignment``, ``gyro-scale --method slew``).

The body (= camera) rate follows a :class:`gyrostar.mocks.trajectory.Jitter` profile
(one sinusoid per axis); attitude truth comes from :func:`gyrostar.mocks.trajectory.integrate`.
Each exposure (start ``k / camera_hz``, length from the simulator preset) is exposed by
:class:`gyrostar.mocks.sky.Sky` with the rates over the exposure (so centroids are the
smeared, exposure-averaged ones); Gaussian centroid noise is added to the identified stars
(V ≤ ``mag_limit``, catalog identities kept: identification is not under test here), they
are unprojected with the camera model and QUEST (:func:`gyrostar.core.quest.quest`) gives
the measured attitude, stamped at mid-exposure.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

DEG = np.pi / 180.0


@dataclass
class SlewTruth:
    profile: object            # RateProfile (body rates, rad/s)
    q0: np.ndarray             # attitude at t = 0
    t_cam: np.ndarray          # exposure mid-times (s, true time)
    q_cam: np.ndarray          # measured attitudes at t_cam (QUEST)
    q_cam_true: np.ndarray     # true attitudes at t_cam
    n_stars: np.ndarray        # stars used per frame


def slew_profile(amplitude_dps=(10.0, 8.0, 6.0), period_s=(2.0, 2.7, 3.3)):
    """Back-and-forth slew: one sinusoid per body axis (rates in °/s, periods in s)."""
    from ...mocks.trajectory import Constant, Jitter

    return Jitter(Constant((0.0, 0.0, 0.0)), tuple(a * DEG for a in amplitude_dps),
                  tuple(1.0 / p for p in period_s), (0.0, 0.7, 1.9))


def simulate_attitudes(duration_s: float, camera_hz: float, seed: int, preset: str = "xing2012",
                       mag_limit: float = 6.5, centroid_noise_px: float = 0.05, profile=None,
                       progress_step=None) -> SlewTruth:
    """Measured camera attitudes over a slew (see the module docstring)."""
    from ...camera import unproject_many
    from ...catalog import load_catalog
    from ...core.quest import quest
    from ...mocks.sim_preset import load_preset
    from ...mocks.sky import Sky
    from ...mocks.trajectory import integrate, random_attitudes

    rng = np.random.default_rng(seed)
    profile = slew_profile() if profile is None else profile
    pre = load_preset(preset)
    cat = load_catalog("hip2", mag_limit)
    sky = Sky(cat, pre, seed=seed)
    index = {int(i): k for k, i in enumerate(cat.ids)}
    t_exp = pre.detector.exposure_s
    n = int(duration_s * camera_hz)
    t_start = np.arange(n) / camera_hz
    q0 = random_attitudes(1, rng)[0]
    q_start = integrate(q0, profile, t_start)
    t_mid = t_start + 0.5 * t_exp
    q_mid_true = integrate(q0, profile, np.concatenate([[0.0], t_mid]))[1:]
    params = pre.camera.as_array()
    m_seg = 8
    q_meas = np.empty((n, 4))
    used = np.zeros(n, np.int64)
    for k in range(n):
        seg_t = t_start[k] + (np.arange(m_seg) + 0.5) * t_exp / m_seg
        truth = sky.expose(q_start[k], omega=profile.rate(seg_t)).truth
        sel = truth.in_field & (truth.vmag <= mag_limit)
        uv = truth.uv[sel] + centroid_noise_px * rng.standard_normal((sel.sum(), 2))
        body = unproject_many(params, np.ascontiguousarray(uv))
        ref = cat.vectors[[index[int(i)] for i in truth.ids[sel]]]
        used[k] = sel.sum()
        if used[k] < 3:
            q_meas[k] = np.nan
        else:
            q_meas[k], _ = quest(body, np.ascontiguousarray(ref), np.ones(len(body)))
        if progress_step is not None:
            progress_step()
    ok = np.isfinite(q_meas[:, 0])
    return SlewTruth(profile, q0, t_mid[ok], q_meas[ok], q_mid_true[ok], used[ok])
