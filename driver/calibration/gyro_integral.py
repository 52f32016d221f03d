"""Integral of a sampled gyro rate at arbitrary times (piecewise-linear rate, exact).

``GyroIntegral(t, w).at(te)`` is ``∫_{t[0]}^{te} ω dt`` (rad, per axis) for the rate signal
that is linear between samples; ``rate(te)`` is that signal; ``one_axis(t0, t1)`` says which
windows turn about one fixed axis, ``rotation_windows(t0, t1)`` which windows' integral is
their rotation vector (one axis, less than :data:`MAX_WINDOW_ANGLE`). Times in seconds (any
clock, increasing), rates (N, 3) rad/s.
"""

from __future__ import annotations

import numpy as np

from ..errors import ConfigError

MAX_WINDOW_ANGLE = np.radians(170.0)   # rad: a window turning more has no unique rotation vector
ONE_AXIS_MIN_TURN = np.radians(10.0)   # rad: windows turning less are taken as they are
ONE_AXIS_MAX_CROSS = np.radians(1.0)   # rad/s: rate off the window's own axis at any sample, at most
                                       # (the BMI088's noise is ~0.1 °/s per sample, its offset ~0.05 °/s)


class GyroIntegral:
    """Cumulative trapezoid integral of (N, 3) rates with sub-sample evaluation."""

    def __init__(self, t: np.ndarray, w: np.ndarray):
        self.t = np.asarray(t, float)
        self.w = np.asarray(w, float)
        if self.t.ndim != 1 or self.w.shape != (len(self.t), 3) or len(self.t) < 2:
            raise ConfigError(f"gyro record must be t (N,) and rates (N, 3); got {self.t.shape}, {self.w.shape}")
        if np.any(np.diff(self.t) <= 0):
            raise ConfigError("gyro timestamps must increase strictly")
        if not np.all(np.isfinite(self.w)):
            raise ConfigError("gyro rates contain NaN or infinite samples")
        dt = np.diff(self.t)[:, None]
        self.cum = np.concatenate([np.zeros((1, 3)), np.cumsum(0.5 * (self.w[1:] + self.w[:-1]) * dt, axis=0)])
        self.slope = np.diff(self.w, axis=0) / dt

    def _index(self, te: np.ndarray) -> np.ndarray:
        if np.any(te < self.t[0]) or np.any(te > self.t[-1]):
            raise ConfigError(f"times {te.min():.6f}..{te.max():.6f} s fall outside the gyro record "
                              f"{self.t[0]:.6f}..{self.t[-1]:.6f} s")
        return np.clip(np.searchsorted(self.t, te, side="right") - 1, 0, len(self.t) - 2)

    def at(self, te: np.ndarray) -> np.ndarray:
        """∫ ω dt from the first sample to each time in ``te`` (K,) → (K, 3) rad."""
        te = np.asarray(te, float)
        j = self._index(te)
        h = (te - self.t[j])[:, None]
        return self.cum[j] + self.w[j] * h + 0.5 * self.slope[j] * h * h

    def rate(self, te: np.ndarray) -> np.ndarray:
        """Linearly interpolated rate at ``te`` (K,) → (K, 3) rad/s."""
        te = np.asarray(te, float)
        j = self._index(te)
        return self.w[j] + self.slope[j] * (te - self.t[j])[:, None]

    def one_axis(self, t0: np.ndarray, t1: np.ndarray) -> np.ndarray:
        """(K,) bool: the window ``t0[k]..t1[k]`` turns about one fixed axis, so its integral
        ``at(t1) − at(t0)`` is its rotation vector — no sample in it turns faster than
        :data:`ONE_AXIS_MAX_CROSS` about an axis across the window's net one — or it turns
        less than :data:`ONE_AXIS_MIN_TURN`. Rotations about different axes do not add as
        vectors: a window across two fast slews (a rest the camera missed), or one that ends
        2° into the next slew after 148° of this one, is off by 1.7° — the net turn is 0.99
        of the path length there, so a length test does not see it."""
        t0, t1 = np.asarray(t0, float), np.asarray(t1, float)
        net = self.at(t1) - self.at(t0)
        turn = np.linalg.norm(net, axis=1)
        ok = np.ones(len(t0), bool)
        for k in np.flatnonzero(turn >= ONE_AXIS_MIN_TURN):
            axis = net[k] / turn[k]
            w = self.w[np.searchsorted(self.t, t0[k]):np.searchsorted(self.t, t1[k], side="right")]
            cross = w - np.outer(w @ axis, axis)
            ok[k] = not len(w) or float(np.sqrt((cross * cross).sum(axis=1)).max()) <= ONE_AXIS_MAX_CROSS
        return ok

    def rotation_windows(self, t0: np.ndarray, t1: np.ndarray) -> np.ndarray:
        """(K,) bool: the window's integral ``at(t1) − at(t0)`` is its rotation vector — it
        turns about one fixed axis (:meth:`one_axis`) and by less than
        :data:`MAX_WINDOW_ANGLE` (a rotation near 180° has no unique rotation vector). The
        windows the slew fits (gyro scale, alignment) can use."""
        turn = np.linalg.norm(self.at(np.asarray(t1, float)) - self.at(np.asarray(t0, float)), axis=1)
        return (turn < MAX_WINDOW_ANGLE) & self.one_axis(t0, t1)
