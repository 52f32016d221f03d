"""How commands report: one JSON object on stdout with --json, human text otherwise.

With ``--json`` the JSON object is the only thing on stdout; human text and progress bars
go to stderr. Without it, human text goes to stdout.
"""

from __future__ import annotations

import json
import math
import sys
from contextlib import contextmanager
from typing import Any

from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn


def human_console(args) -> Console:
    """Console for human-readable text: stderr in --json mode, stdout otherwise."""
    return Console(stderr=bool(getattr(args, "json", False)), highlight=False)


def _clean(obj: Any) -> Any:
    """Make numpy scalars/arrays and non-finite floats JSON-safe."""
    if isinstance(obj, dict):
        return {str(k): _clean(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_clean(v) for v in obj]
    if hasattr(obj, "tolist"):
        return _clean(obj.tolist())
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj


def emit(args, result: dict, human: str | None = None) -> None:
    """Report a command's figures: JSON to stdout (with --json) and/or human text."""
    if human:
        human_console(args).print(human)
    if getattr(args, "json", False):
        sys.stdout.write(json.dumps(_clean(result), sort_keys=False) + "\n")
        sys.stdout.flush()


@contextmanager
def progress(args, description: str, total: int | None):
    """A rich progress bar on stderr (silent with -q); yields ``advance(n=1)``."""
    quiet = getattr(args, "verbose", 0) < 0
    bar = Progress(TextColumn("[bold]{task.description}"), BarColumn(), MofNCompleteColumn(),
                   TimeRemainingColumn(), console=Console(stderr=True), transient=True,
                   disable=quiet)
    with bar:
        task = bar.add_task(description, total=total)
        yield lambda n=1: bar.advance(task, n)
