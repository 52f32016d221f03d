"""Helpers shared by the orbit-environment tests: scenarios with chosen hazards, attitudes
relative to the Sun, the Earth and the Moon, and the scenarios' true attitude over time."""

import math

import numpy as np
from gyrostar.attitude import quat_from_boresight
from gyrostar.hil import config as hc


def scenario(*hazards: str, **tables) -> hc.Scenario:
    """A scenario with ``hazards`` switched on; ``tables``: {table: {key: value}} changes."""
    scen = hc.Scenario(name="env-test", duration_s=60.0)
    for h in hazards:
        getattr(scen, h).enabled = True
    for table, keys in tables.items():
        for k, v in keys.items():
            setattr(getattr(scen, table), k, v)
    scen.validate()
    return scen


def unit(v) -> np.ndarray:
    v = np.asarray(v, float)
    return v / np.linalg.norm(v)


def pointing(direction, roll_deg: float = 0.0) -> np.ndarray:
    """ICRS→body quaternion with the boresight along ``direction`` (ICRS)."""
    d = unit(direction)
    return np.asarray(quat_from_boresight(math.atan2(d[1], d[0]), math.asin(d[2]), math.radians(roll_deg)))


def away_from(src, angle_deg: float, other) -> np.ndarray:
    """A direction ``angle_deg`` from ``src``, turned from it towards ``other`` (all ICRS)."""
    s = unit(src)
    e = unit(np.asarray(other, float) - (np.asarray(other, float) @ s) * s)
    a = math.radians(angle_deg)
    return math.cos(a) * s + math.sin(a) * e


def scenario_attitudes(scen: hc.Scenario, t: np.ndarray) -> np.ndarray:
    """The scenario's true attitude (ICRS→body) at scenario times ``t`` (s)."""
    from gyrostar.hil.flatsat import scenario_profile
    from gyrostar.mocks.trajectory import integrate

    q0 = np.asarray(quat_from_boresight(math.radians(scen.ra_deg), math.radians(scen.dec_deg),
                                        math.radians(scen.roll_deg)))
    return integrate(q0, scenario_profile(scen), np.concatenate([[0.0], np.asarray(t, float)]))[1:]
