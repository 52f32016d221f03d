"""Shared synthetic slew for the gyro–camera fits: one sinusoid per camera axis."""

import numpy as np
import pytest
from gyrostar.attitude import quat_propagate

AMP_RAD_S = np.radians([8.0, 6.0, 5.0])
PERIOD_S = np.array([2.0, 2.6, 3.1])


def sine_rate(t: np.ndarray) -> np.ndarray:
    """Body rate (n, 3) rad/s, camera axes, at times ``t`` (s)."""
    return AMP_RAD_S * np.sin(2 * np.pi * np.asarray(t)[:, None] / PERIOD_S)


@pytest.fixture
def sine_slew():
    """``make(fs, duration) -> (t, q, rate_fn)``: attitudes ICRS → camera (n, 4) at ``fs`` Hz
    over ``duration`` s, integrated from identity (trapezoidal rate per step), and the rate
    function they follow."""

    def make(fs: float, duration: float):
        t = np.arange(0, duration, 1 / fs)
        w = sine_rate(t)
        q = np.empty((len(t), 4))
        q[0] = [0, 0, 0, 1]
        for i in range(1, len(t)):
            q[i] = quat_propagate(q[i - 1], 0.5 * (w[i] + w[i - 1]), 1 / fs)
        return t, q, sine_rate

    return make
