"""A Monte Carlo campaign of the coupled loop on Dask: submit runs, gather rows, sum up.

:class:`Cluster` gives a ``dask.distributed.Client``: a ``LocalCluster`` of ``workers``
single-threaded processes by default, or an existing scheduler by address. A scheduler
off this machine is used only over TLS (``distributed.security.Security`` with the
certificates named by the caller): a Dask scheduler runs whatever code it is sent.

:func:`run_campaign` submits one task per seed (key ``mc-<duration>-<seed>``, retried once
if it raises in the worker; a task of a lost worker is rescheduled by Dask, costing only
that worker's runs), collects rows as they complete, and :func:`summarize` reduces them.
Rows depend only on their seed, so :func:`results_sha256` is the same for any number of
workers and any scheduler.
"""

from __future__ import annotations

import hashlib
import ipaddress
import json
import math
from dataclasses import dataclass

import numpy as np

from ...errors import ConfigError, DeviceError, NotAvailableError
from .metrics import ERR_EDGES_ARCSEC, RATE_BINS, hist_percentiles

# columns that describe how a run was executed, not what it computed: left out of the hash
NOT_HASHED = ("wall_s",)
CONNECT_TIMEOUT_S = 10.0


@dataclass(frozen=True)
class TlsFiles:
    """PEM files for a TLS connection to a remote scheduler."""

    ca_file: str
    cert: str
    key: str


def is_loopback(address: str) -> bool:
    from distributed.comm.addressing import get_address_host

    host = get_address_host(address if "://" in address else f"tcp://{address}")
    if host in ("localhost", ""):
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


class Cluster:
    """Dask client for a campaign; use as a context manager."""

    def __init__(self, workers: int = 2, scheduler: str | None = None, tls: TlsFiles | None = None,
                 config_path: str | None = None):
        from ..dask_quiet import distributed, local_client, silence_logs
        from .worker import preload_plugin

        self.cluster = None
        if scheduler:
            security = None
            if tls is not None:
                from distributed.security import Security

                security = Security(tls_ca_file=tls.ca_file, tls_client_cert=tls.cert, tls_client_key=tls.key,
                                    require_encryption=True)
                if not scheduler.startswith("tls://"):
                    scheduler = "tls://" + scheduler.split("://", 1)[-1]
            elif not is_loopback(scheduler):
                raise ConfigError(f"--scheduler {scheduler}: a scheduler beyond loopback is used only over TLS "
                                  "(give --tls-ca, --tls-cert and --tls-key; see docs/MONTECARLO.md)")
            silence_logs()
            try:
                self.client = distributed().Client(scheduler, security=security, timeout=CONNECT_TIMEOUT_S)
            except (OSError, TimeoutError) as exc:
                raise DeviceError(f"--scheduler {scheduler}: no Dask scheduler answered within "
                                  f"{CONNECT_TIMEOUT_S:.0f} s ({type(exc).__name__})") from None
        else:
            self.cluster, self.client = local_client(workers, dashboard_address=":0")
        self.client.register_plugin(preload_plugin(config_path))
        self.config_path = config_path

    @property
    def n_workers(self) -> int:
        return len(self.client.scheduler_info().get("workers", {}))

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def close(self) -> None:
        self.client.close()
        if self.cluster is not None:
            self.cluster.close()


def run_campaign(cluster: Cluster, seeds, duration_s: float, on_row=None, rows: list | None = None,
                 orbit: bool = False) -> list[dict]:
    """Rows of every seed (sorted by seed); ``on_row(row)`` as each completes. ``rows``: a
    list the rows are collected into as they come (what ran is kept if the wait is interrupted).
    ``orbit``: the orbit cases (``eval loop --orbit``)."""
    from dask.distributed import as_completed

    from .worker import run_case

    prefix = "mco" if orbit else "mc"
    futures = [cluster.client.submit(run_case, int(s), float(duration_s), cluster.config_path, bool(orbit),
                                     pure=False, key=f"{prefix}-{duration_s:g}-{int(s)}", retries=1) for s in seeds]
    rows = [] if rows is None else rows
    try:
        for fut in as_completed(futures):
            row = fut.result()
            rows.append(row)
            if on_row is not None:
                on_row(row)
    finally:
        for f in futures:
            f.cancel()
    return sorted(rows, key=lambda r: r["seed"])


def _canonical(value):
    if isinstance(value, np.ndarray):
        return [_canonical(v) for v in value.tolist()]
    if isinstance(value, (list, tuple)):
        return [_canonical(v) for v in value]
    if isinstance(value, (float, np.floating)):
        return "nan" if math.isnan(value) else float(value).hex()
    if isinstance(value, (np.integer, np.bool_)):
        return value.item()
    return value


def results_sha256(rows: list[dict]) -> str:
    """SHA-256 over the rows' computed values (floats exactly, as hex), seed order."""
    h = hashlib.sha256()
    for row in sorted(rows, key=lambda r: r["seed"]):
        h.update(json.dumps({k: _canonical(v) for k, v in sorted(row.items()) if k not in NOT_HASHED},
                            sort_keys=True).encode())
        h.update(b"\n")
    return h.hexdigest()


def _pct(values, qs=(50, 95)) -> dict:
    v = np.asarray([x for x in values if x is not None and np.isfinite(x)], float)
    return {f"p{q}": (float(np.percentile(v, q)) if v.size else None) for q in qs}


def summarize(rows: list[dict], worst: int = 5) -> dict:
    """The campaign's distributions (see docs/MONTECARLO.md for each figure)."""
    ok = [r for r in rows if not r["failed"]]
    hist = np.sum([r["err_hist"] for r in ok], axis=0) if ok else np.zeros(len(ERR_EDGES_ARCSEC) - 1)
    rate_sq = np.sum([r["rate_sq"] for r in ok], axis=0) if ok else np.zeros(len(RATE_BINS))
    rate_n = np.sum([r["rate_n"] for r in ok], axis=0) if ok else np.zeros(len(RATE_BINS))
    by_rate = {b: {"rms_arcsec": (float(math.sqrt(s / n)) if n else None), "outputs": int(n)}
               for b, s, n in zip(RATE_BINS, rate_sq, rate_n)}
    ranked = sorted(ok, key=lambda r: -(r["worst_arcsec"] if np.isfinite(r["worst_arcsec"]) else -1.0))
    profiles = sorted({r["profile"] for r in rows})
    return {
        "runs": len(rows),
        "failed": len(rows) - len(ok),
        "failures": [{"seed": r["seed"], "reason": r["reason"]} for r in rows if r["failed"]][:20],
        "wrong_attitude_runs": int(sum(r["wrong_attitude"] for r in ok)),
        "wrong_id_runs": int(sum(r["wrong_id"] for r in ok)),
        "attitude_error_arcsec": hist_percentiles(hist, (50, 95, 99)),
        "attitude_error_arcsec_by_rate_dps": by_rate,
        "attitude_error_1sigma_arcsec_per_run": _pct([r["err_1sigma_arcsec"] for r in ok], (50, 95, 99)),
        "mid_exposure_error_arcsec": _pct([r["mid_exposure_error_arcsec"] for r in ok]),
        "time_to_first_fix_s": _pct([r["ttff_s"] for r in ok]),
        "runs_without_fix": int(sum(not np.isfinite(r["ttff_s"]) for r in ok)),
        "coast_growth_arcsec_per_s": _pct([r["coast_growth_arcsec_per_s"] for r in ok]),
        "overruns": int(sum(r["overruns"] for r in ok)),
        "samples_lost": int(sum(r["samples_lost"] for r in ok)),
        "runs_by_profile": {p: sum(r["profile"] == p for r in rows) for p in profiles},
        "worst_runs": [{"seed": r["seed"], "profile": r["profile"], "peak_rate_dps": round(r["peak_rate_dps"], 3),
                        "worst_arcsec": r["worst_arcsec"], "wrong_attitude": r["wrong_attitude"]}
                       for r in ranked[:worst]],
        "results_sha256": results_sha256(rows),
    } | (summarize_hazards(ok) if any("hazard" in r for r in rows) else {})


def summarize_hazards(ok: list[dict]) -> dict:
    """Orbit campaign figures, per hazard and over all runs (docs/MONTECARLO.md, "Orbit")."""

    def block(rs):
        hist = np.sum([r["valid_err_hist"] for r in rs], axis=0) if rs else np.zeros(len(ERR_EDGES_ARCSEC) - 1)
        outages = [x for r in rs for x in r["outages_s"]]
        return {"runs": len(rs),
                "availability": {"mean": float(np.mean([r["availability"] for r in rs])) if rs else None,
                                 **{k: v for k, v in _pct([r["availability"] for r in rs], (5, 50)).items()}},
                "blinded_fraction_mean": float(np.mean([r["blinded_fraction"] for r in rs])) if rs else None,
                "reacquire_s": {"outages": len(outages), **_pct(outages)},
                "runs_unrecovered": int(sum(np.isfinite(r["unrecovered_s"]) for r in rs)),
                "error_while_valid_arcsec": hist_percentiles(hist, (50, 95, 99)),
                "valid_outside_covariance_outputs": int(sum(r["valid_wrong_outputs"] for r in rs)),
                "wrong_attitude_runs": int(sum(r["wrong_attitude"] for r in rs)),
                "wrong_id_runs": int(sum(r["wrong_id"] for r in rs)),
                "radiation_hits_expected": float(np.nansum([r["hits_expected"] for r in rs])),
                "spots_rejected_hit": int(sum(r["spots_rejected_hit"] for r in rs)),
                "frames_blinded": int(sum(r["frames_blinded"] for r in rs)),
                "saa_seconds": float(sum(r["saa_seconds"] for r in rs))}

    hazards = sorted({r["hazard"] for r in ok})
    worst = sorted(ok, key=lambda r: (-r["valid_wrong_outputs"], r["availability"]))[:5]
    return {"orbit": {"all": block(ok), "by_hazard": {h: block([r for r in ok if r["hazard"] == h]) for h in hazards},
                      "worst_runs": [{"seed": r["seed"], "hazard": r["hazard"], "profile": r["profile"],
                                      "availability": r["availability"], "valid_outside_covariance_outputs":
                                      r["valid_wrong_outputs"], "worst_arcsec": r["worst_arcsec"]} for r in worst]}}


def write_table(rows: list[dict], path) -> None:
    """Per-run rows as Parquet (pyarrow), one row per run; pandas reads it with read_parquet."""
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError as exc:
        raise NotAvailableError(f"pyarrow is needed for the per-run table: {exc}") from exc
    cols = {k: [(_as_py(r[k])) for r in rows] for k in rows[0]} if rows else {}
    pq.write_table(pa.table(cols), str(path))


def _as_py(v):
    if isinstance(v, np.ndarray):
        return v.tolist()
    if isinstance(v, (np.floating, np.integer, np.bool_)):
        return v.item()
    return v
