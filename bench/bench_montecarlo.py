"""Loop Monte Carlo throughput: runs per second with 2 Dask workers against 1 worker.

Both campaigns run the same seeds (fast-mode flatsat runs of ``DURATION_S`` each) on a
``LocalCluster`` started and warmed (numba caches, catalog, star index) before the clock
starts; the figure is the wall time per run. ``ratio`` = (wall per run, 1 worker) / (wall
per run, 2 workers): the speed-up from the second worker (2.0 is the ideal on 2 cores;
issue 17 asks ≥ 1.7). Both campaigns' results hashes must agree, or the suite raises.
"""

from __future__ import annotations

import time

from gyrostar.hil.eval_loop import run_seeds
from gyrostar.hil.montecarlo.campaign import Cluster, results_sha256, run_campaign

DURATION_S = 10.0


def _campaign(workers: int, seeds) -> tuple[float, str, int]:
    with Cluster(workers) as cluster:
        cluster.client.wait_for_workers(workers, timeout=120)
        # one run per worker first: the worker plugin has loaded the caches, this loads the rest
        run_campaign(cluster, [10_000_000 + k for k in range(workers)], DURATION_S)
        t0 = time.perf_counter()
        rows = run_campaign(cluster, seeds, DURATION_S)
        wall = time.perf_counter() - t0
    failed = sum(r["failed"] for r in rows)
    return wall / len(seeds), results_sha256(rows), failed


def run(quick: bool = False) -> dict:
    seeds = run_seeds(7, 4 if quick else 12)
    one, h1, f1 = _campaign(1, seeds)
    two, h2, f2 = _campaign(2, seeds)
    if h1 != h2:
        raise RuntimeError(f"results differ between 1 and 2 workers: {h1[:12]} vs {h2[:12]}")
    note = f"{len(seeds)} runs of {DURATION_S:g} s; failed {f1}/{f2}; sha256 {h1[:12]}"
    return {"loop_mc_2_workers_vs_1": {"us": two * 1e6, "baseline_us": one * 1e6, "ratio": one / two,
                                       "runs_per_min_1": 60.0 / one, "runs_per_min_2": 60.0 / two, "note": note}}
