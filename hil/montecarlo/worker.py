"""What a Dask worker runs: one simulated flatsat run of one drawn case, in fast mode.

:func:`run_case` is a pure function of ``(seed, duration_s, config_path)``: it draws the
case, runs the loop on the simulated clock (``gyrostar run --fast``), and returns the
run's row (plain Python and numpy values, see :func:`gyrostar.hil.montecarlo.metrics.run_metrics`).
A run that raises is returned as a row with ``failed=True`` and the one-line reason,
so one bad case never stops a campaign.

:func:`preload_plugin` is a Dask worker plugin: each worker process loads the numba caches
(the loop's warm-up) and the catalog and star index once, when it starts, not per run.
"""

from __future__ import annotations

import logging
import tempfile
import time
from pathlib import Path

import numpy as np

log = logging.getLogger(__name__)

_PROCESS: dict = {}     # per worker process: catalog vectors by id, warm-up done


def preload(config_path: str | None = None) -> dict:
    """Load the numba caches and the catalog/star index into this process (once)."""
    if "star_vec" in _PROCESS:
        return _PROCESS["info"]
    from ...camera import camera_preset
    from ...catalog import load_catalog
    from ...loop.coupled import warmup
    from .. import config as hc
    from .. import flatsat

    t0 = time.perf_counter()
    cfg = hc.load_flatsat(config_path)
    warmup()
    cat = load_catalog(cfg.sim.catalog, cfg.loop.mag_limit + 1.5)
    flatsat.star_index(cfg, camera_preset(cfg.sim.preset))
    _PROCESS["star_vec"] = dict(zip(cat.ids.tolist(), cat.vectors))
    _PROCESS["info"] = {"preload_s": time.perf_counter() - t0}
    return _PROCESS["info"]


def preload_plugin(config_path: str | None = None):
    """A Dask ``WorkerPlugin`` that runs :func:`preload` when each worker starts."""
    from distributed.diagnostics.plugin import WorkerPlugin

    class Preload(WorkerPlugin):
        idempotent = True
        name = "gyrostar-montecarlo-preload"

        def setup(self, worker=None):
            from ..dask_quiet import ignore_sigint

            # Ctrl-C in a terminal reaches the whole process group: the campaign's own process
            # stops the runs and closes the cluster; a worker ignores it (no traceback of its own)
            ignore_sigint()
            preload(config_path)

    return Preload()


def run_case(seed: int, duration_s: float, config_path: str | None = None, orbit: bool = False) -> dict:
    """Row of run ``seed``: the case's description and its figures (never raises). ``orbit``:
    the orbit case (:mod:`gyrostar.hil.montecarlo.orbit_cases`), with its hazard's figures."""
    from .cases import draw_case
    from .metrics import empty_metrics, empty_orbit_metrics

    ocase = None
    if orbit:
        from .orbit_cases import draw_orbit_case

        ocase = draw_orbit_case(seed, duration_s)
        case = ocase.loop
    else:
        case = draw_case(seed, duration_s)
    row = {"seed": int(seed), "profile": case.profile, "peak_rate_dps": case.peak_rate_dps,
           "ra_deg": case.ra_deg, "dec_deg": case.dec_deg, "roll_deg": case.roll_deg,
           "false_spots": len(case.false_spots), "link_faults": len(case.link_faults),
           "arw_dps_rthz": case.gyro_overrides["noise_density_dps_rthz"],
           "bias_instability_dph": case.gyro_overrides["bias_instability_dph"], "failed": False, "reason": "",
           **empty_metrics(), "frames": 0, "overruns": 0, "samples_lost": 0, "wall_s": np.nan,
           "mid_exposure_error_arcsec": np.nan}
    if ocase is not None:
        row.update(hazard=ocase.hazard, hazard_angle_deg=ocase.angle_deg, temperature_c=ocase.temperature_c,
                   epoch_utc=ocase.epoch_utc, **empty_orbit_metrics())
    try:
        row.update(_run(case, duration_s, config_path, ocase))
    except Exception as exc:  # noqa: BLE001 - a failed run is a result, reported with its reason
        row.update(failed=True, reason=f"{type(exc).__name__}: {exc}".splitlines()[0][:300])
    return row


def _run(case, duration_s: float, config_path: str | None, ocase=None) -> dict:
    from .. import config as hc
    from ..runner import run_flatsat
    from .cases import case_scenario
    from .metrics import orbit_metrics, run_metrics

    preload(config_path)
    cfg = hc.load_flatsat(config_path)
    if ocase is not None:
        from .orbit_cases import orbit_case_scenario

        scen = orbit_case_scenario(ocase, duration_s)
    else:
        scen = case_scenario(case, duration_s)
    with tempfile.TemporaryDirectory(prefix="gyrostar-mc-") as tmp:
        res = run_flatsat(cfg, scen, duration=duration_s, seed=case.seed, folder=Path(tmp), fast=True,
                          plots=False, status=False, record=False, keep_arrays=True)
    arrays = res.pop("arrays")
    m = run_metrics(arrays["out"], arrays["truth"], arrays["t0"], arrays["camera"], _PROCESS["star_vec"])
    if ocase is not None:
        m.update(orbit_metrics(arrays["out"], arrays["truth"], arrays["t0"], res))
    return {**m, "frames": int(res.get("frames") or 0), "overruns": int(res.get("overruns") or 0),
            "samples_lost": int(res.get("samples_lost") or 0), "wall_s": float(res.get("wall_s") or np.nan),
            "mid_exposure_error_arcsec": float(res.get("mid_exposure_error_arcsec_1sigma") or np.nan)}
