"""A circular low Earth orbit with the Sun and the Moon: where they and the Earth are seen from.

Frames and units: positions are geocentric GCRS (≈ ICRS axes, the star catalog's) in km;
directions are unit vectors in the same axes; times are scenario seconds ``t`` from the
orbit's epoch (UTC).

* The orbit: circular, radius R_E + altitude, inclination i, right ascension of the ascending
  node Ω (given, or from the local time of the ascending node and the Sun's right ascension at
  the epoch), argument of latitude ``phase + n·t`` with n = √(μ/a³). No J2 precession (a few
  degrees a day: nothing over a run of minutes).
* The Sun and the Moon: astropy's built-in ephemeris (``get_body(..., ephemeris='builtin')``:
  VSOP87 / ELP2000 series inside ERFA, nothing downloaded; IERS auto-download is switched off
  for the call), tabulated every 60 s over the run and interpolated linearly (Moon error ~1 m).
  The Moon's direction from the spacecraft includes its parallax (up to 1° in LEO).
* The Earth: its limb is at ρ = asin(R_E / r) from nadir; the spacecraft is in the Earth's
  shadow when it is behind the Earth inside the shadow cylinder of radius R_E (the umbra's
  taper over a LEO altitude is 0.3°: left out).
* The sub-satellite point (for the South Atlantic Anomaly): latitude from the position, longitude
  from it and the Greenwich mean sidereal time (IAU 1982 linear term, UTC for UT1: < 0.01°).
"""

from __future__ import annotations

import math

import numpy as np

R_EARTH_KM = 6378.137          # WGS-84 equatorial radius
MU_EARTH_KM3_S2 = 398600.4418  # GM of the Earth
R_MOON_KM = 1737.4             # mean radius of the Moon
R_SUN_KM = 695700.0            # nominal solar radius (IAU 2015 B3)
AU_KM = 149597870.7
EPHEMERIS_STEP_S = 60.0


def ephemeris_table(epoch_utc: str, t0_s: float, t1_s: float, step_s: float = EPHEMERIS_STEP_S):
    """``(t (n,), sun (n, 3), moon (n, 3))``: geocentric GCRS positions (km) of the Sun and the
    Moon from astropy's built-in ephemeris at scenario times ``t0_s … t1_s`` (s from the epoch)."""
    import astropy.units as u
    from astropy.coordinates import get_body
    from astropy.time import Time
    from astropy.utils import iers

    n = max(2, int(math.ceil((t1_s - t0_s) / step_s)) + 1)
    t = t0_s + step_s * np.arange(n)
    import warnings

    with iers.conf.set_temp("auto_download", False), iers.conf.set_temp("auto_max_age", None), \
            warnings.catch_warnings():
        # beyond the leap-second table's horizon ERFA calls a year "dubious": a possible
        # future leap second (1 s) is far below this model's accuracy
        warnings.filterwarnings("ignore", message=".*dubious year")
        times = Time(epoch_utc, scale="utc") + t * u.s
        sun = get_body("sun", times, ephemeris="builtin").cartesian.xyz.to_value(u.km).T
        moon = get_body("moon", times, ephemeris="builtin").cartesian.xyz.to_value(u.km).T
    return t, np.ascontiguousarray(sun), np.ascontiguousarray(moon)


def epoch_jd(epoch_utc: str) -> float:
    """Julian date (UTC) of an ISO 8601 epoch."""
    from datetime import UTC, datetime

    dt = datetime.fromisoformat(epoch_utc)
    if dt.tzinfo is not None:
        dt = dt.astimezone(UTC).replace(tzinfo=None)
    j2000 = datetime(2000, 1, 1, 12, 0, 0)
    return 2451545.0 + (dt - j2000).total_seconds() / 86400.0


def gmst_deg(jd_ut: float) -> float:
    """Greenwich mean sidereal time (deg) at Julian date ``jd_ut`` (IAU 1982, linear terms)."""
    return (280.46061837 + 360.98564736629 * (jd_ut - 2451545.0)) % 360.0


class CircularOrbit:
    """The spacecraft's position and the Sun and Moon over a run; see the module docstring.

    ``cfg``: an :class:`gyrostar.hil.config.OrbitConfig` (or any object with its attributes);
    ``horizon_s``: the ephemeris is tabulated over [-60, horizon_s + 60] s and extended on demand.
    """

    def __init__(self, cfg, horizon_s: float = 600.0):
        self.cfg = cfg
        self.altitude_km = float(cfg.altitude_km)
        self.a_km = R_EARTH_KM + self.altitude_km
        self.n_rad_s = math.sqrt(MU_EARTH_KM3_S2 / self.a_km ** 3)
        self.period_s = 2.0 * math.pi / self.n_rad_s
        self.inc = math.radians(cfg.inclination_deg)
        self.jd0 = epoch_jd(cfg.epoch_utc)
        self._table = None
        self._extend(-EPHEMERIS_STEP_S, max(float(horizon_s), 1.0) + EPHEMERIS_STEP_S)
        if cfg.raan_deg is not None:
            self.raan = math.radians(cfg.raan_deg)
        else:
            s = self.sun_km(0.0)
            self.raan = math.atan2(s[1], s[0]) + math.radians(15.0 * (cfg.ltan_h - 12.0))
        self.u0 = math.radians(cfg.phase_deg)
        cO, sO, ci, si = math.cos(self.raan), math.sin(self.raan), math.cos(self.inc), math.sin(self.inc)
        self._p = np.array([cO, sO, 0.0])               # towards the ascending node
        self._q = np.array([-sO * ci, cO * ci, si])     # 90° ahead in the orbit plane

    def _extend(self, t0: float, t1: float) -> None:
        if self._table is not None:
            t0 = min(t0, self._table[0][0])
            t1 = max(t1, self._table[0][-1] + 600.0)
        self._table = ephemeris_table(self.cfg.epoch_utc, t0, t1)

    def _interp(self, which: int, t: float) -> np.ndarray:
        tt = self._table[0]
        if not tt[0] <= t <= tt[-1]:
            self._extend(t - EPHEMERIS_STEP_S, t + EPHEMERIS_STEP_S)
            tt = self._table[0]
        i = min(int((t - tt[0]) // EPHEMERIS_STEP_S), len(tt) - 2)
        w = (t - tt[i]) / (tt[i + 1] - tt[i])
        tab = self._table[which]
        return (1.0 - w) * tab[i] + w * tab[i + 1]

    def sun_km(self, t: float) -> np.ndarray:
        """Geocentric Sun (km, GCRS) at scenario time ``t`` (s)."""
        return self._interp(1, t)

    def moon_km(self, t: float) -> np.ndarray:
        """Geocentric Moon (km, GCRS) at scenario time ``t`` (s)."""
        return self._interp(2, t)

    def position_km(self, t: float) -> np.ndarray:
        """Spacecraft position (km, GCRS) at scenario time ``t`` (s)."""
        u = self.u0 + self.n_rad_s * t
        return self.a_km * (math.cos(u) * self._p + math.sin(u) * self._q)

    def in_shadow(self, t: float) -> bool:
        """The spacecraft is in the Earth's shadow (cylinder of radius R_E behind the Earth)."""
        r = self.position_km(t)
        s = self.sun_km(t)
        s = s / np.linalg.norm(s)
        along = float(r @ s)
        return along < 0.0 and float(np.linalg.norm(r - along * s)) < R_EARTH_KM

    def subpoint_deg(self, t: float) -> tuple[float, float]:
        """(latitude, east longitude) of the sub-satellite point, deg (spherical Earth)."""
        r = self.position_km(t)
        lat = math.degrees(math.asin(r[2] / np.linalg.norm(r)))
        lon = math.degrees(math.atan2(r[1], r[0])) - gmst_deg(self.jd0 + t / 86400.0)
        return lat, (lon + 180.0) % 360.0 - 180.0

    def earth_radius_angle(self) -> float:
        """Angular radius ρ of the Earth's disk seen from the orbit (rad)."""
        return math.asin(R_EARTH_KM / self.a_km)
