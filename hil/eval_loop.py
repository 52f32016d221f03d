"""``gyrostar eval loop``: Monte Carlo of the coupled loop on Dask (docs/MONTECARLO.md).

Each run draws its own case from its seed (:mod:`gyrostar.hil.montecarlo.cases`) and runs
the simulated flatsat in fast mode; the campaign reports distributions, the worst runs
with their seeds, a per-run Parquet table and plots.
"""

from __future__ import annotations

import time
from pathlib import Path

HELP = "Monte Carlo of the coupled loop: many simulated flatsat runs on Dask, faster than real time"


def configure(parser) -> None:
    from ..cli.argtypes import seed as seed_type
    from ..cli.main import add_json

    parser.add_argument("--runs", type=int, default=200, help="number of runs (default: 200)")
    parser.add_argument("--duration", type=float, default=30.0, metavar="S",
                        help="flatsat seconds per run (default: 30, at least 10)")
    parser.add_argument("--seed", type=seed_type, default=1,
                        help="campaign seed: run k uses seed SEED*100000 + k (default: 1)")
    parser.add_argument("--workers", type=int, default=2, help="LocalCluster worker processes (default: 2)")
    parser.add_argument("--scheduler", default=None, metavar="ADDRESS",
                        help="an existing Dask scheduler (tcp://127.0.0.1:8786; beyond loopback only with TLS)")
    parser.add_argument("--tls-ca", default=None, metavar="PEM", help="CA certificate for a TLS scheduler")
    parser.add_argument("--tls-cert", default=None, metavar="PEM", help="client certificate for a TLS scheduler")
    parser.add_argument("--tls-key", default=None, metavar="PEM", help="client key for a TLS scheduler")
    parser.add_argument("--config", default=None, metavar="TOML",
                        help="flatsat config (default: the built-in simulated flatsat)")
    parser.add_argument("--orbit", action="store_true",
                        help="orbit cases: a LEO orbit with the Sun, the Moon, the Earth, radiation and temperature, "
                             "each run aimed at one hazard; availability and re-acquisition per hazard")
    parser.add_argument("--out", default=None, metavar="DIR",
                        help="folder for results.parquet, summary.json and plots (default: runs/mc-<time>)")
    parser.add_argument("--plot", default=None, metavar="DIR", help="write the plots to DIR (default: --out)")
    add_json(parser)


def _preflight(args) -> None:
    """Refuse up front (exit 2) a flatsat config the campaign's fast runs cannot use: every
    run would fail for the same reason."""
    from ..paths import check_cache_writable
    from . import config as hc
    from .flatsat import preflight

    check_cache_writable()          # every worker compiles the kernels and loads the star index into it
    cfg = hc.load_flatsat(args.config)
    seed = run_seeds(args.seed, 1)[0]
    if getattr(args, "orbit", False):
        from .montecarlo.orbit_cases import draw_orbit_case, orbit_case_scenario

        scen = orbit_case_scenario(draw_orbit_case(seed, args.duration), args.duration)
    else:
        scen = hc.load_scenario(f"mc:{seed}@{args.duration:g}")
    preflight(cfg, scen, simulated_clock=True, devices=False)


def local_workers(asked: int, runs: int) -> int:
    """Worker processes of a local cluster: ``--workers`` capped at the runs (a worker more has
    nothing to do) and at this process's CPUs (one more only shares a CPU, and each holds the
    catalog, the star index and the numba kernels: ~0.3 GB); the cap is logged."""
    import logging

    from ..errors import ConfigError
    from .host_cpus import cpus

    if asked < 1:
        raise ConfigError(f"--workers must be ≥ 1, got {asked}")
    n = min(asked, runs, cpus())
    if n < asked:
        logging.getLogger("gyrostar").warning("--workers %d capped at %d (%d runs, %d CPUs)", asked, n, runs, cpus())
    return n


def run_seeds(campaign_seed: int, runs: int) -> list[int]:
    """The run seeds of a campaign: independent of the worker count and the order of runs."""
    return [campaign_seed * 100_000 + k for k in range(runs)]


def run(args) -> int:
    import json
    from datetime import UTC, datetime

    from ..cli.output import emit, json_safe
    from ..errors import ConfigError
    from ..paths import runs_dir
    from .montecarlo.campaign import Cluster, TlsFiles, summarize, write_table
    from .montecarlo.plots import write_plots

    if args.runs < 1:
        raise ConfigError(f"--runs must be ≥ 1, got {args.runs}")
    try:
        import pyarrow  # noqa: F401 - the per-run table is written with it: fail before the runs, not after
    except ImportError as exc:
        from ..errors import NotAvailableError

        raise NotAvailableError(f"pyarrow is needed for the per-run table (pip install 'pyarrow>=14'): {exc}") from None
    from .config import MAX_SCENARIO_S

    if not (args.duration >= 10.0 and args.duration <= MAX_SCENARIO_S):     # a scenario's own bound
        raise ConfigError(f"--duration must be a number of seconds in [10, {MAX_SCENARIO_S:g}], got {args.duration}")
    tls_given = [args.tls_ca, args.tls_cert, args.tls_key]
    if any(tls_given) and not all(tls_given):
        raise ConfigError("--tls-ca, --tls-cert and --tls-key go together")
    for flag, value in (("--tls-ca", args.tls_ca), ("--tls-cert", args.tls_cert), ("--tls-key", args.tls_key)):
        if value and not Path(value).is_file():
            raise ConfigError(f"{flag} {value}: no such file")
    tls = TlsFiles(args.tls_ca, args.tls_cert, args.tls_key) if all(tls_given) else None
    _preflight(args)
    folder = Path(args.out) if args.out else runs_dir() / f"mc-{datetime.now(UTC):%Y%m%dT%H%M%S}"
    for kept in ("summary.json", "results.parquet"):
        if (folder / kept).exists():
            raise ConfigError(f"--out {folder} already holds a campaign ({kept}); choose another --out")
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ConfigError(f"--out {folder}: {exc.strerror}") from None
    seeds = run_seeds(args.seed, args.runs)
    workers = local_workers(args.workers, args.runs) if not args.scheduler else args.workers
    t0 = time.perf_counter()
    rows: list[dict] = []
    interrupted = False
    with Cluster(workers, args.scheduler, tls, args.config) as cluster:
        n_workers = cluster.n_workers
        try:
            _with_progress(args, cluster, seeds, rows)
        except KeyboardInterrupt:       # keep and report the runs that finished
            interrupted = True
    wall = time.perf_counter() - t0
    rows.sort(key=lambda r: r["seed"])
    if interrupted and not rows:
        raise KeyboardInterrupt
    res = summarize(rows)
    res.update(wall_s=round(wall, 2), runs_per_minute=round(60.0 * len(rows) / wall, 2), workers=n_workers,
               duration_s=args.duration, seed=args.seed, orbit_cases=bool(args.orbit),
               scheduler=args.scheduler or f"LocalCluster({workers} processes)")
    res["results_table"] = str(folder / "results.parquet")
    _write_json(folder / "summary.json", json.dumps(json_safe(res), indent=2))   # first: nothing after can lose it
    write_table(rows, folder / "results.parquet")
    res["plots"] = [str(p) for p in write_plots(rows, Path(args.plot) if args.plot else folder)]
    _write_json(folder / "summary.json", json.dumps(json_safe(res), indent=2))
    if interrupted:
        res["interrupted"] = True
        _write_json(folder / "summary.json", json.dumps(json_safe(res), indent=2))
        import logging

        logging.getLogger("gyrostar").error("interrupted after %d of %d runs: their results are in %s",
                                            len(rows), len(seeds), folder)
        emit(args, res)
        return 130
    emit(args, res, _text(res))
    return 1 if res["wrong_attitude_runs"] or res["wrong_id_runs"] else 0


def _write_json(path: Path, text: str) -> None:
    """``text`` as ``path``, whole or not at all (a full disk leaves no 0-byte summary)."""
    from ..files import whole_or_nothing

    with whole_or_nothing(path) as part:
        part.write_text(text)


def _with_progress(args, cluster, seeds, rows):
    from rich.console import Console
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

    from .montecarlo.campaign import run_campaign

    quiet = getattr(args, "verbose", 0) < 0
    console = Console(stderr=True)
    bar = Progress(TextColumn("[bold]loop Monte Carlo"), BarColumn(), MofNCompleteColumn(),
                   TextColumn("failed {task.fields[failed]}"), TimeRemainingColumn(),
                   console=console, transient=True, disable=quiet)
    # off a terminal (a pipe, a log file, a batch job) the bar draws nothing until the end: a line instead
    lines = None if quiet or console.is_terminal else ProgressLines(len(seeds))
    with bar:
        task = bar.add_task("runs", total=len(seeds), failed=0)
        failed = [0]

        def on_row(row):
            failed[0] += bool(row["failed"])
            bar.update(task, advance=1, failed=failed[0])
            if lines is not None:
                lines.done(failed[0])

        return run_campaign(cluster, seeds, args.duration, on_row, rows, orbit=args.orbit)


class ProgressLines:
    """Plain progress lines for a campaign off a terminal: runs done of the total, failures,
    time so far and left, at most one every ``every_s`` (and the last run's)."""

    def __init__(self, total: int, every_s: float = 10.0, clock=time.monotonic):
        import logging

        self.total, self.every_s, self.clock = total, every_s, clock
        self.t0 = clock()
        self.last = None
        self.n = 0
        self.log = logging.getLogger("gyrostar")

    def done(self, failed: int) -> None:
        from ..logs import NOTICE

        self.n += 1
        now = self.clock()
        if self.n < self.total and self.last is not None and now - self.last < self.every_s:
            return
        self.last = now
        spent = now - self.t0
        left = spent / self.n * (self.total - self.n)
        self.log.log(NOTICE, "loop Monte Carlo: %d of %d runs done, %d failed, %.0f s so far, about %.0f s left",
                     self.n, self.total, failed, spent, left)


def _fmt(v, spec=".2f") -> str:
    return "—" if v is None else format(v, spec)


def _text(r: dict) -> str:
    e = r["attitude_error_arcsec"]
    f = r["time_to_first_fix_s"]
    lines = [f"loop Monte Carlo: {r['runs']} runs of {r['duration_s']:g} s on {r['workers']} workers, "
             f"{r['wall_s']:.1f} s wall ({r['runs_per_minute']:.1f} runs/min)",
             f"  failed {r['failed']}   wrong attitude runs {r['wrong_attitude_runs']}   "
             f"wrong id runs {r['wrong_id_runs']}",
             f"  attitude error (cross-boresight, TRACK) p50 {_fmt(e['p50'])}″  p95 {_fmt(e['p95'])}″  "
             f"p99 {_fmt(e['p99'])}″",
             f"  time to first fix p50 {_fmt(f['p50'])} s  p95 {_fmt(f['p95'])} s "
             f"({r['runs_without_fix']} runs without a fix)",
             "  by rate (°/s): " + "  ".join(f"{b}: {_fmt(v['rms_arcsec'])}″" for b, v in
                                             r["attitude_error_arcsec_by_rate_dps"].items()),
             "  worst runs (re-run: gyrostar run --fast --scenario mc:SEED@DURATION --seed SEED): "
             + ", ".join(f"{w['seed']} ({w['profile']}, {_fmt(w['worst_arcsec'], '.0f')}″)" for w in r["worst_runs"]),
             f"  results {r['results_table']}   sha256 {r['results_sha256'][:16]}…"]
    if r.get("orbit_cases"):
        lines[-2] = lines[-2].replace("mc:SEED", "mco:SEED")
        lines[-1:-1] = _orbit_text(r)
    return "\n".join(lines)


def _orbit_text(r: dict) -> list[str]:
    o = r["orbit"]
    out = ["  orbit: hazard   runs  availability mean (p5)   re-acquire p50/p95 s (outages, unrecovered)   "
           "error while valid p50/p95″   valid outside cov   hits expected/rejected"]
    for name, b in [("all", o["all"])] + list(o["by_hazard"].items()):
        a, q, e = b["availability"], b["reacquire_s"], b["error_while_valid_arcsec"]
        out.append(f"    {name:<8} {b['runs']:>4}  {_fmt(a['mean'], '.3f')} ({_fmt(a['p5'], '.3f')})"
                   f"   {_fmt(q['p50'])}/{_fmt(q['p95'])} ({q['outages']}, {b['runs_unrecovered']})"
                   f"   {_fmt(e['p50'])}/{_fmt(e['p95'])}   {b['valid_outside_covariance_outputs']}"
                   f"   {b['radiation_hits_expected']:.0f}/{b['spots_rejected_hit']}")
    out.append("  orbit worst runs (re-run: gyrostar run --fast --scenario mco:SEED@DURATION --seed SEED): "
               + ", ".join(f"{w['seed']} ({w['hazard']}, {w['profile']}, avail {_fmt(w['availability'], '.2f')})"
                           for w in o["worst_runs"]))
    return out
