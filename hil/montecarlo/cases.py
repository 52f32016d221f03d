"""One Monte Carlo case of the coupled loop, drawn from its seed alone.

:func:`draw_case` turns a run seed into a :class:`LoopCase` (sky pointing, rate profile,
gyro and camera errors, false spots, link faults); :func:`case_scenario` turns the case
into the :class:`gyrostar.hil.config.Scenario` that ``gyrostar run`` runs. Every draw comes
from ``numpy.random.default_rng(SeedSequence([seed, CASE_STREAM]))`` in a fixed order, so a
case depends on its seed only (never on the worker, the order of runs or the run count),
and ``gyrostar run --scenario FILE --seed SEED`` re-runs any case from the TOML that
:func:`case_toml` writes. The distributions are listed in docs/MONTECARLO.md.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from .. import config as hc

CASE_STREAM = 0x6C6F6F70  # "loop": the case's own stream, apart from the simulator's seed use

PROFILES = ("rest", "slew", "tumble", "starless")
PROFILE_P = (0.25, 0.40, 0.15, 0.20)

# BMI088 gyro die, datasheet ranges (BST-BMI088-DS001): noise density 0.014 °/s/√Hz typical;
# bias instability ~2 °/h class; the zero-rate offset (±1 °/s), sensitivity tolerance (±1 %)
# and cross-axis sensitivity (±1 %) are drawn by the simulator from the run seed
# (gyrostar.mocks.gyro_truth "bmi088" set), the offset at its calibrated residual (below).
ARW_RANGE_DPS_RTHZ = (0.010, 0.018)
# the ±1 °/s zero-rate offset is removed by the start-up calibration (gyrostar calibrate
# gyro-static); what is left (calibration error + drift with temperature, 0.015 °/s/K in the
# datasheet, over a few K) is drawn per run by the simulator with this σ per axis
RESIDUAL_BIAS_SIGMA_DPS = 0.01
BIAS_INSTABILITY_RANGE_DPH = (1.0, 4.0)

# camera errors left after calibration (the issue-16 acceptance tolerances): focal length
# within 0.02 %, principal point within 0.3 px per axis
FOCAL_TOL_REL = 2e-4
PRINCIPAL_TOL_PX = 0.3

MAX_SLEW_DPS = 10.0
TUMBLE_DPS = (20.0, 40.0)        # beyond the tracker's rate limit: forces a re-acquisition
FALSE_SPOTS_MAX = 3              # stray-light glints, fixed on the sensor
FALSE_SPOT_VMAG = (3.5, 7.0)
LINK_FAULT_RATE_PER_MIN = 1.0    # link-corruption bursts per minute (Poisson)
LINK_FAULT_BYTE_RATE = 0.01      # fraction of bytes corrupted during a burst


@dataclasses.dataclass(frozen=True)
class LoopCase:
    """A drawn case: everything that differs between Monte Carlo runs (SI-free units as named)."""

    seed: int
    profile: str
    ra_deg: float
    dec_deg: float
    roll_deg: float
    peak_rate_dps: float
    segments: tuple            # ((seconds, rate_dps (3,), rate_end_dps (3,) | None), ...)
    eclipse: tuple             # ((start_s, end_s), ...)
    gyro_overrides: dict       # GyroErrorParams fields on top of the "bmi088" set
    camera_errors: dict        # focal_rel, cx_px, cy_px (true camera minus nominal)
    false_spots: tuple         # ((col_px, row_px, vmag), ...) fixed on the sensor
    link_faults: tuple         # ((at_s, seconds, byte_rate), ...)


def _unit(rng: np.random.Generator) -> np.ndarray:
    v = rng.normal(size=3)
    return v / np.linalg.norm(v)


def _cross_axis(rng: np.random.Generator, roll_fraction: float = 0.2) -> np.ndarray:
    """A rate direction mostly across the boresight (body z), with some roll."""
    phi = rng.uniform(0.0, 2.0 * math.pi)
    v = np.array([math.cos(phi), math.sin(phi), rng.uniform(-roll_fraction, roll_fraction)])
    return v / np.linalg.norm(v)


def draw_case(seed: int, duration_s: float, width_px: int = 1024, height_px: int = 1024) -> LoopCase:
    """The case of run ``seed`` for a run of ``duration_s`` seconds (sensor size for the spots)."""
    if duration_s < 10.0:
        raise ValueError(f"a Monte Carlo run needs at least 10 s, got {duration_s}")
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), CASE_STREAM]))
    ra = rng.uniform(0.0, 360.0)
    dec = math.degrees(math.asin(rng.uniform(-1.0, 1.0)))
    roll = rng.uniform(0.0, 360.0)
    profile = PROFILES[int(rng.choice(len(PROFILES), p=PROFILE_P))]
    d = float(duration_s)
    segs: list = []
    eclipse: list = []
    peak = 0.0
    if profile == "rest":
        peak = rng.uniform(0.0, 0.05)
        segs.append((d, tuple(peak * _unit(rng)), None))
    elif profile == "slew":
        peak = rng.uniform(0.5, MAX_SLEW_DPS)
        w = tuple(peak * _cross_axis(rng))
        t_rest = rng.uniform(2.0, 4.0)
        ramp = rng.uniform(0.5, 2.0)
        hold = rng.uniform(2.0, max(2.0, 0.5 * d - 2 * ramp))
        segs += [(t_rest, (0.0, 0.0, 0.0), None), (ramp, (0.0, 0.0, 0.0), w), (hold, w, None),
                 (ramp, w, (0.0, 0.0, 0.0))]
        segs.append((max(1.0, d - t_rest - 2 * ramp - hold), (0.0, 0.0, 0.0), None))
    elif profile == "tumble":
        peak = rng.uniform(*TUMBLE_DPS)
        w = tuple(peak * _unit(rng))
        t_rest = rng.uniform(3.0, 5.0)
        spin = rng.uniform(1.0, 3.0)
        segs += [(t_rest, (0.0, 0.0, 0.0), None), (0.5, (0.0, 0.0, 0.0), w), (spin, w, None),
                 (0.5, w, (0.0, 0.0, 0.0))]
        segs.append((max(1.0, d - t_rest - 1.0 - spin), (0.0, 0.0, 0.0), None))
    else:  # starless: a stretch with no stars (Earth or Sun in the baffle) while at rest
        peak = rng.uniform(0.0, 0.05)
        segs.append((d, tuple(peak * _unit(rng)), None))
        start = rng.uniform(5.0, max(5.5, d - 8.0))
        eclipse.append((start, start + rng.uniform(1.0, min(5.0, d - start - 1.0))))
    gyro = {"bias_sigma_dps": RESIDUAL_BIAS_SIGMA_DPS,
            "noise_density_dps_rthz": float(rng.uniform(*ARW_RANGE_DPS_RTHZ)),
            "bias_instability_dph": float(rng.uniform(*BIAS_INSTABILITY_RANGE_DPH))}
    camera = {"focal_rel": float(rng.uniform(-FOCAL_TOL_REL, FOCAL_TOL_REL)),
              "cx_px": float(rng.uniform(-PRINCIPAL_TOL_PX, PRINCIPAL_TOL_PX)),
              "cy_px": float(rng.uniform(-PRINCIPAL_TOL_PX, PRINCIPAL_TOL_PX))}
    n_spots = int(rng.integers(0, FALSE_SPOTS_MAX + 1))
    spots = tuple((float(rng.uniform(20, width_px - 20)), float(rng.uniform(20, height_px - 20)),
                   float(rng.uniform(*FALSE_SPOT_VMAG))) for _ in range(n_spots))
    faults = []
    t = rng.exponential(60.0 / LINK_FAULT_RATE_PER_MIN)
    while t < d - 1.0:
        faults.append((float(t), float(rng.uniform(0.1, 0.5)), LINK_FAULT_BYTE_RATE))
        t += rng.exponential(60.0 / LINK_FAULT_RATE_PER_MIN)
    return LoopCase(seed=int(seed), profile=profile, ra_deg=float(ra), dec_deg=float(dec), roll_deg=float(roll),
                    peak_rate_dps=float(peak),
                    segments=tuple((float(s), tuple(float(x) for x in w0),
                                    None if w1 is None else tuple(float(x) for x in w1)) for s, w0, w1 in segs),
                    eclipse=tuple((float(a), float(b)) for a, b in eclipse), gyro_overrides=gyro,
                    camera_errors=camera, false_spots=spots, link_faults=tuple(faults))


def case_scenario(case: LoopCase, duration_s: float) -> hc.Scenario:
    """The scenario that runs ``case`` (validated like a scenario file)."""
    segs = [hc.Segment(seconds=s, rate_dps=w0, rate_end_dps=w1) for s, w0, w1 in case.segments]
    faults = [hc.Fault(kind="link-corruption", at_s=a, seconds=s, rate=r) for a, s, r in case.link_faults]
    scen = hc.Scenario(
        name=f"mc-{case.seed}", description=f"Monte Carlo case {case.seed}: {case.profile}, "
        f"peak {case.peak_rate_dps:.2f} deg/s", duration_s=float(duration_s), ra_deg=case.ra_deg,
        dec_deg=case.dec_deg, roll_deg=case.roll_deg, segments=segs, eclipse=[list(e) for e in case.eclipse],
        faults=faults, gyro_errors="bmi088", gyro_overrides=dict(case.gyro_overrides),
        false_spots=[list(s) for s in case.false_spots])
    scen.validate()
    return scen


def case_toml(case: LoopCase, duration_s: float) -> str:
    """The scenario of ``case`` as TOML, for ``gyrostar run --scenario FILE --seed SEED``."""
    import tomli_w

    from ...config import to_dict

    d = to_dict(case_scenario(case, duration_s))
    return tomli_w.dumps({k: v for k, v in d.items() if v is not None})
