"""One orbit Monte Carlo case (``gyrostar eval loop --orbit``), drawn from its seed alone.

A case is the loop case of :func:`gyrostar.hil.montecarlo.cases.draw_case` (rate profile,
gyro and camera errors, glints, link faults, star-less stretches) placed on a low Earth orbit
with every hazard of :mod:`gyrostar.mocks.environment` switched on — stray light from the Sun,
the sunlit Earth and the Moon, the Moon's disk, radiation hits and new hot pixels, the sensor's
temperature — and one hazard it is aimed at (:data:`HAZARDS`):

* ``sun``: the boresight ``SUN_OFFSET_DEG`` from the baffle's exclusion angle to the Sun
  (a dawn–dusk orbit, never in the Earth's shadow);
* ``moon``: the Moon's centre inside the field (``MOON_OFFSET_DEG`` from the boresight);
* ``earth``: the boresight ``LIMB_OFFSET_DEG`` from the baffle's exclusion angle above the sunlit
  Earth's limb (the Earth's light comes through the same baffle);
* ``saa``: the sub-satellite point inside the South Atlantic Anomaly at the run's middle;
* ``quiet``: a random pointing away from the Sun, the Earth and the Moon (the orbit's
  background hazards only: radiation outside the SAA, hot pixels, temperature).

The orbit's phase and the node, the pointing, the temperature and the hazard come from
``numpy.random.default_rng(SeedSequence([seed, ORBIT_STREAM]))``, apart from the loop case's
own stream, so ``mco:SEED@DURATION`` is the same case wherever it runs. The angles are those
at scenario time 0; the drawn rate profile then moves the boresight (a slew or a tumble may
carry it into or out of the hazard, as in orbit).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from .. import config as hc
from .cases import LoopCase, case_scenario, draw_case

ORBIT_STREAM = 0x6F726269    # "orbi"
HAZARDS = ("sun", "moon", "earth", "saa", "quiet")
HAZARD_P = (0.2, 0.2, 0.2, 0.2, 0.2)
SUN_OFFSET_DEG = (-3.0, 12.0)        # sun angle − exclusion angle at the start
MOON_OFFSET_DEG = (0.5, 3.5)         # Moon centre from the boresight (the field's half width: 4.4°)
LIMB_OFFSET_DEG = (-3.0, 12.0)       # boresight elevation above the Earth's limb − exclusion angle
CLEAR_DEG = 10.0                     # other bodies at least this far beyond their limits (Sun, Earth: exclusion)
SAA_CORE_LAT_DEG = (-40.0, -10.0)    # where in the SAA box the run's middle is put
SAA_CORE_LON_DEG = (-70.0, 20.0)
TEMPERATURE_C = (-10.0, 40.0)        # mean sensor temperature
SWING_C = (0.0, 10.0)                # over one orbit
EPOCH_DAYS = 365.0                   # epochs drawn over a year from EPOCH0 (all Moon phases, seasons)
EPOCH0 = "2026-01-01T00:00:00"


@dataclasses.dataclass(frozen=True)
class OrbitCase:
    """An orbit case: the loop case (its pointing replaced) and the environment drawn."""

    loop: LoopCase
    hazard: str
    epoch_utc: str
    ltan_h: float | None
    raan_deg: float | None
    phase_deg: float
    temperature_c: float
    swing_c: float
    angle_deg: float             # the hazard's angle as drawn (sun − exclusion, Moon offset, limb − exclusion)


def _perp(rng, v):
    a = rng.normal(size=3)
    a -= (a @ v) * v
    return a / np.linalg.norm(a)


def _away(rng, v, w, spread_deg=75.0):
    """A unit axis ⟂ ``v`` pointing away from ``w`` (within ±``spread_deg`` about ``v``): a
    pointing turned from ``v`` towards it stays clear of ``w``."""
    a = -w - (-w @ v) * v
    n = np.linalg.norm(a)
    if n < 1e-9:
        return _perp(rng, v)
    a /= n
    b = np.cross(v, a)
    phi = math.radians(rng.uniform(-spread_deg, spread_deg))
    return math.cos(phi) * a + math.sin(phi) * b


def _rotate_towards(v, axis, angle_rad):
    """``v`` turned by ``angle_rad`` in the plane of ``v`` and the unit ``axis`` ⟂ ``v``."""
    return math.cos(angle_rad) * v + math.sin(angle_rad) * axis


def _angle(a, b):
    return math.degrees(math.acos(max(-1.0, min(1.0, float(a @ b)))))


def _radec(v):
    return math.degrees(math.atan2(v[1], v[0])) % 360.0, math.degrees(math.asin(max(-1.0, min(1.0, v[2]))))


def _epoch(rng) -> str:
    from datetime import datetime, timedelta

    t = datetime.fromisoformat(EPOCH0) + timedelta(seconds=float(rng.uniform(0.0, EPOCH_DAYS * 86400.0)))
    return t.replace(microsecond=0).isoformat()


def _geometry(orbit_cfg):
    """(sun, moon, nadir unit vectors from the spacecraft at t = 0, Earth's angular radius deg)."""
    from ...mocks.orbit import CircularOrbit

    o = CircularOrbit(orbit_cfg, horizon_s=60.0)
    r = o.position_km(0.0)
    sun, moon = o.sun_km(0.0) - r, o.moon_km(0.0) - r
    return (sun / np.linalg.norm(sun), moon / np.linalg.norm(moon), -r / np.linalg.norm(r),
            math.degrees(o.earth_radius_angle()))


def _clear(d, sun, moon, nadir, rho_deg, exclusion_deg, skip=()):
    ok = True
    if "sun" not in skip:
        ok &= _angle(d, sun) > exclusion_deg + CLEAR_DEG
    if "earth" not in skip:
        ok &= _angle(d, nadir) - rho_deg > exclusion_deg + CLEAR_DEG
    if "moon" not in skip:
        ok &= _angle(d, moon) > CLEAR_DEG
    return ok


def _saa_orbit(rng, epoch: str, inc_deg: float, duration_s: float, altitude_km: float):
    """(raan deg, phase deg at t = 0) putting the sub-satellite point inside the SAA core at the
    run's middle: the argument of latitude from the target latitude, the node from its longitude."""
    from ...mocks.orbit import MU_EARTH_KM3_S2, R_EARTH_KM, epoch_jd, gmst_deg

    lat = math.radians(rng.uniform(*SAA_CORE_LAT_DEG))
    lon = rng.uniform(*SAA_CORE_LON_DEG)
    inc = math.radians(inc_deg)
    u = math.asin(max(-1.0, min(1.0, math.sin(lat) / math.sin(inc))))
    if rng.random() < 0.5:
        u = math.pi - u                  # the other pass through that latitude
    ra_point = math.degrees(math.atan2(math.cos(inc) * math.sin(u), math.cos(u)))
    t_mid = 0.5 * duration_s
    raan = (lon + gmst_deg(epoch_jd(epoch) + t_mid / 86400.0) - ra_point) % 360.0
    n = math.sqrt(MU_EARTH_KM3_S2 / (R_EARTH_KM + altitude_km) ** 3)
    phase = math.degrees(u - n * t_mid) % 360.0
    return raan, phase


def draw_orbit_case(seed: int, duration_s: float) -> OrbitCase:
    """The orbit case of run ``seed`` for a run of ``duration_s`` seconds."""
    base = draw_case(seed, duration_s)
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), ORBIT_STREAM]))
    hazard = HAZARDS[int(rng.choice(len(HAZARDS), p=HAZARD_P))]
    temperature = float(rng.uniform(*TEMPERATURE_C))
    swing = float(rng.uniform(*SWING_C))
    orbit_defaults = hc.OrbitConfig()
    excl = hc.StrayLightConfig().exclusion_deg
    inc = orbit_defaults.inclination_deg
    for _attempt in range(200):           # a pointing that meets the hazard and clears the rest
        epoch = _epoch(rng)
        ltan, raan, phase = float(rng.uniform(6.0, 18.0)), None, float(rng.uniform(0.0, 360.0))
        if hazard == "sun":
            ltan = 6.0 if rng.random() < 0.5 else 18.0            # dawn–dusk: always sunlit
        elif hazard == "saa":
            raan, phase = _saa_orbit(rng, epoch, inc, duration_s, orbit_defaults.altitude_km)
            ltan = None
        cfg = dataclasses.replace(orbit_defaults, enabled=True, epoch_utc=epoch, phase_deg=phase,
                                  ltan_h=ltan if ltan is not None else orbit_defaults.ltan_h, raan_deg=raan)
        sun, moon, nadir, rho = _geometry(cfg)
        if hazard == "sun":
            angle = float(rng.uniform(*SUN_OFFSET_DEG))
            d = _rotate_towards(sun, _away(rng, sun, nadir), math.radians(excl + angle))
            skip = ("sun",)
        elif hazard == "moon":
            angle = float(rng.uniform(*MOON_OFFSET_DEG))
            d = _rotate_towards(moon, _perp(rng, moon), math.radians(angle))
            skip = ("moon",)
        elif hazard == "earth":
            angle = float(rng.uniform(*LIMB_OFFSET_DEG))
            d = _rotate_towards(nadir, _away(rng, nadir, sun), math.radians(rho + excl + angle))
            skip = ("earth",)
        else:
            angle = 0.0
            d = rng.normal(size=3)
            d /= np.linalg.norm(d)
            skip = ()
        if _clear(d, sun, moon, nadir, rho, excl, skip):
            break
    else:
        raise ValueError(f"orbit case {seed}: no pointing found for hazard {hazard}")
    ra, dec = _radec(d)
    loop = dataclasses.replace(base, ra_deg=ra, dec_deg=dec)
    return OrbitCase(loop=loop, hazard=hazard, epoch_utc=epoch, ltan_h=ltan, raan_deg=raan, phase_deg=phase,
                     temperature_c=temperature, swing_c=swing, angle_deg=angle)


def orbit_case_scenario(case: OrbitCase, duration_s: float) -> hc.Scenario:
    """The scenario that runs ``case``: the loop case's, with the orbit and every hazard on."""
    scen = case_scenario(case.loop, duration_s)
    o = hc.OrbitConfig(enabled=True, epoch_utc=case.epoch_utc, phase_deg=case.phase_deg,
                       ltan_h=case.ltan_h if case.ltan_h is not None else hc.OrbitConfig().ltan_h,
                       raan_deg=case.raan_deg)
    scen = dataclasses.replace(
        scen, name=f"mco-{case.loop.seed}",
        description=f"orbit Monte Carlo case {case.loop.seed}: {case.hazard} ({case.angle_deg:.2f} deg), "
                    f"{case.loop.profile}, {case.temperature_c:.1f} C",
        orbit=o, stray_light=hc.StrayLightConfig(enabled=True), moon=hc.MoonConfig(enabled=True),
        radiation=hc.RadiationConfig(enabled=True, hot_pixels_per_hour=60.0),
        thermal=hc.ThermalConfig(enabled=True, temperature_c=case.temperature_c, swing_c=case.swing_c))
    scen.validate()
    return scen
