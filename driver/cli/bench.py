"""``gyrostar bench [SUITE ...]``: speed benchmarks from the checkout's ``bench/`` folder.

A suite is ``bench/bench_<name>.py`` exposing ``run(quick: bool) -> dict`` that returns
``{case: {"us": t, "baseline_us": b, "ratio": b / t, ...}}`` — every figure measured in
the same run as its baseline (plain numpy or a peer). Benchmarks need a source checkout.
"""

from __future__ import annotations

import importlib
import sys
import time
from contextlib import contextmanager

from ..errors import ConfigError, NotAvailableError
from ..paths import repo_root
from .main import add_json
from .output import emit


def configure(parser) -> None:
    parser.add_argument("suites", nargs="*", metavar="SUITE", help="suites to run (default: all)")
    parser.add_argument("--quick", action="store_true", help="fewer repetitions")
    parser.add_argument("--list", action="store_true", help="list the suites and exit")
    add_json(parser)


def discover() -> dict:
    root = repo_root()
    if root is None:
        raise NotAvailableError("benchmarks run from a source checkout (bench/ not found)")
    return {p.stem.removeprefix("bench_"): p for p in sorted((root / "bench").glob("bench_*.py"))}


def _load(path):
    """Import a suite by its plain module name from bench/ (so numba's on-disk cache of
    the suite's own jitted baselines can be found again on the next run)."""
    folder = str(path.parent)
    if folder not in sys.path:
        sys.path.insert(0, folder)
    return importlib.import_module(path.stem)


def run(args) -> int:
    suites = discover()
    chosen = args.suites or list(suites)
    unknown = [s for s in chosen if s not in suites]
    if unknown:
        raise ConfigError(f"unknown bench suite(s) {unknown}; known: {list(suites)}")
    if args.list:
        emit(args, {"suites": list(suites)}, "\n".join(suites) or "(no suites)")
        return 0
    from rich.table import Table

    result = {}
    table = Table(title="gyrostar bench")
    for col in ("suite", "case", "µs", "baseline µs", "ratio", "note"):
        table.add_column(col)
    with suite_progress(args, len(chosen)) as next_suite:
        for name in chosen:
            next_suite(name)
            t0 = time.perf_counter()
            cases = _load(suites[name]).run(quick=args.quick)
            result[name] = cases
            for case, fig in cases.items():
                table.add_row(name, case, _f(fig.get("us")), _f(fig.get("baseline_us")),
                              _f(fig.get("ratio")), str(fig.get("note", "")))
            result[name]["_suite_seconds"] = round(time.perf_counter() - t0, 2)
    from .output import table_console

    table_console(args.json).print(table)
    emit(args, result)
    return 0


@contextmanager
def suite_progress(args, n_suites: int):
    """Progress across suites on stderr (suite k of n, its name, time elapsed); silent with -q
    or off a terminal. Yields ``next_suite(name)``."""
    from rich.console import Console
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, SpinnerColumn, TextColumn, TimeElapsedColumn

    console = Console(stderr=True)
    bar = Progress(SpinnerColumn(), TextColumn("[bold]bench[/] {task.description}"), BarColumn(),
                   MofNCompleteColumn(), TimeElapsedColumn(), console=console, transient=True,
                   disable=getattr(args, "verbose", 0) < 0 or not console.is_terminal)
    with bar:
        task = bar.add_task("", total=n_suites)
        started = [False]

        def next_suite(name: str) -> None:
            if started[0]:
                bar.advance(task)
            started[0] = True
            bar.update(task, description=name)

        yield next_suite
        bar.advance(task)


def _f(value) -> str:
    return "" if value is None else f"{value:.3g}"
