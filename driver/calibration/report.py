"""What every calibration command shares: its common arguments, the report folder, the
parameter table (value, truth, error) and its emission as JSON / human text."""

from __future__ import annotations

import datetime as _dt
import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import ConfigError


def calibration_out(text: str) -> Path:
    """argparse type of ``--out``: a path whose existing file must be a calibration file,
    checked before any fit runs (a foreign file is refused, never overwritten)."""
    import argparse

    from .calfile import check_target

    path = Path(text)
    try:
        check_target(path)
    except ConfigError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return path


def add_common_args(parser, input_help: str, live: bool = False) -> None:
    """``INPUT``/``--simulate``/``--seed``/``--toml``(``--out``)/``--report``/``--json`` for one
    command; ``--live`` only where the command records from a device itself (``live``)."""
    from ..cli.argtypes import seed as seed_type
    from ..cli.main import add_json

    parser.add_argument("input", nargs="?", type=Path, help=input_help)
    parser.add_argument("--simulate", action="store_true",
                        help="generate simulated data with known truth and calibrate on it")
    parser.add_argument("--seed", type=seed_type, default=1, help="random seed for --simulate (default 1)")
    if live:
        parser.add_argument("--live", action="store_true", help="record from the connected device")
    parser.add_argument("--toml", "--out", dest="toml", type=calibration_out, default=None,
                        help="calibration TOML to update: this command replaces its own table and keeps the others "
                             "(default: calibration.toml in the report folder)")
    parser.add_argument("--report", type=Path, default=None,
                        help="report folder for plots and products (default: runs/calibrate/NAME-TIME)")
    parser.add_argument("--no-plots", action="store_true", help="skip the report plots")
    add_json(parser)


def check_source(args) -> str:
    """Which data source the arguments ask for: 'simulate', 'live' or 'file'."""
    live = bool(getattr(args, "live", False))
    chosen = [bool(args.simulate), live, args.input is not None]
    if sum(chosen) != 1:
        raise ConfigError("give exactly one of: an input file, --live, or --simulate" if hasattr(args, "live")
                          else "give exactly one of: an input file or --simulate")
    if args.input is not None and not Path(args.input).exists():
        raise ConfigError(f"INPUT {args.input} does not exist")
    return "simulate" if args.simulate else "live" if live else "file"


def _is_npy(path: Path) -> bool:
    with open(path, "rb") as fh:
        return fh.read(6) == b"\x93NUMPY"


def read_npz(path, needed: set[str] | tuple[str, ...], what: str = "INPUT") -> dict:
    """The arrays of an ``.npz`` input, every one of ``needed`` present and non-empty; a file
    that is not an ``.npz`` archive, an empty archive or a missing/empty array is a
    :class:`ConfigError` naming ``what`` (the argument) and the file."""
    import pickle
    import zipfile

    path = Path(path)
    if path.is_dir():
        raise ConfigError(f"{what} {path} is a folder, not an .npz file")
    from ..files import check_regular

    check_regular(path, what)       # a FIFO or /dev/zero: refused, never opened
    if not zipfile.is_zipfile(path) and not _is_npy(path):
        raise ConfigError(f"{what} {path} is not an .npz archive (no zip header)")
    try:
        loaded = np.load(path, allow_pickle=False)
        if not hasattr(loaded, "files"):
            raise ConfigError(f"{what} {path} is a single .npy array, not an .npz archive of named arrays")
        with loaded as z:
            arrays = {k: z[k] for k in z.files}
    except ConfigError:
        raise
    except (ValueError, OSError, EOFError, zipfile.BadZipFile, pickle.UnpicklingError) as exc:
        raise ConfigError(f"{what} {path} is not a readable .npz archive ({type(exc).__name__}: {exc})"[:300]) from exc
    if not arrays:
        raise ConfigError(f"{what} {path} is an empty .npz archive (needs arrays {', '.join(sorted(needed))})")
    missing = sorted(set(needed) - set(arrays))
    if missing:
        raise ConfigError(f"{what} {path} lacks arrays {missing} (has {sorted(arrays)})")
    empty = sorted(k for k in needed if arrays[k].size == 0)
    if empty:
        raise ConfigError(f"{what} {path}: arrays {empty} are empty")
    return arrays


def report_dir(args, name: str) -> Path:
    """The report folder (created): ``--report`` or ``runs/calibrate/NAME-YYYYmmddTHHMMSS``."""
    from ..paths import runs_dir

    if args.report is not None:
        path = Path(args.report)
        if path.exists() and not path.is_dir():
            raise ConfigError(f"--report {path} exists and is not a folder")
    else:
        stamp = _dt.datetime.now(_dt.UTC).strftime("%Y%m%dT%H%M%S")
        path = runs_dir() / "calibrate" / f"{name}-{stamp}"
    new = [p for p in (path, *path.parents) if not p.exists()]
    CREATED.extend(reversed(new))          # outermost first: removed deepest first
    path.mkdir(parents=True, exist_ok=True)
    return path


CREATED: list[Path] = []     # report folders made by this process (removed again if a command fails empty)


def remove_empty_reports() -> None:
    """After a failed command: remove the report folders it created and left empty."""
    while CREATED:
        path = CREATED.pop()
        try:
            path.rmdir()             # only an empty folder: never loses anything
        except OSError:
            pass


@dataclass
class ParamTable:
    """Estimated parameters in report order: name -> {value, unit, truth?, error?}."""

    rows: dict = field(default_factory=dict)

    def add(self, name: str, value, unit: str, truth=None, error=None) -> None:
        """Record one parameter; ``error`` defaults to ``value − truth`` when truth is given."""
        row = {"value": _plain(value), "unit": unit}
        if truth is not None:
            row["truth"] = _plain(truth)
            row["error"] = _plain(np.asarray(value, float) - np.asarray(truth, float) if error is None else error)
        self.rows[name] = row

    def human(self, title: str) -> str:
        from rich.markup import escape

        lines = [f"[bold]{title}[/bold]", f"{'parameter':<28} {'value':>14} {'truth':>14} {'error':>12}  unit"]
        for name, row in self.rows.items():
            vals = [np.atleast_1d(np.asarray(row.get(k, np.nan), float)).ravel() for k in ("value", "truth", "error")]
            for i in range(len(vals[0])):
                label = name if len(vals[0]) == 1 else f"{name}[{i}]"
                cells = [f"{v[i]:.7g}" if i < len(v) and np.isfinite(v[i]) else "" for v in vals]
                lines.append(escape(f"{label:<28} {cells[0]:>14} {cells[1]:>14} {cells[2]:>12}  {row['unit']}"))
            for key, val in row.items():       # further columns (1-σ, limits) under their row
                if key not in ("value", "unit", "truth", "error"):
                    vals = np.atleast_1d(np.asarray(val, float)).ravel()
                    lines.append(escape(f"  {key:<26} " + " ".join(f"{v:.4g}" for v in vals)))
        return "\n".join(lines)


def _plain(v):
    a = np.asarray(v)
    return a.item() if a.ndim == 0 else a.tolist()


def finish(args, name: str, table: ParamTable, extra: dict, folder: Path, checks: dict | None = None) -> int:
    """Emit the result (JSON object / human table), save ``result.json`` in the report
    folder, and return the exit code: 1 if any acceptance check (simulated runs) failed."""
    from ..cli.output import emit

    result = {"calibration": name, "parameters": table.rows, **extra, "report": str(folder)}
    if checks:
        result["acceptance"] = checks
    (folder / "result.json").write_text(json.dumps(_json_safe(result), indent=2))
    human = table.human(f"gyrostar calibrate {name}")
    if checks:
        human += "\n" + "\n".join(f"  {'PASS' if c['pass'] else 'FAIL'}  {k}: {c['value']:.4g} "
                                  f"(limit {c['limit']:.4g} {c['unit']})" for k, c in checks.items())
    human += f"\nreport: {folder}"
    emit(args, result, human)
    return 0 if not checks or all(c["pass"] for c in checks.values()) else 1


def check(value: float, limit: float, unit: str) -> dict:
    """One acceptance criterion: |value| ≤ limit."""
    return {"value": float(abs(value)), "limit": float(limit), "unit": unit, "pass": bool(abs(value) <= limit)}


def _json_safe(obj):
    if isinstance(obj, dict):
        return {str(k): _json_safe(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_json_safe(v) for v in obj]
    if hasattr(obj, "tolist"):
        return obj.tolist()
    if isinstance(obj, float) and not np.isfinite(obj):
        return None
    return obj


def new_figure(*args, **kwargs):
    """A matplotlib figure on the Agg backend (no display needed)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt.subplots(*args, **kwargs)


def save_figure(fig, path: Path) -> Path:
    import matplotlib.pyplot as plt

    from ..files import whole_or_nothing

    fig.tight_layout()
    try:
        with whole_or_nothing(path) as part:      # a full disk leaves no 0-byte PNG
            fig.savefig(part, dpi=110, format="png")
    finally:
        plt.close(fig)
    return path
