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

OFF_TERMINAL_WIDTH = 400     # columns a table may take in a pipe or a file (rich's default there is 80)


def human_console(args) -> Console:
    """Console for human-readable text: stderr in --json mode, stdout otherwise."""
    return table_console(bool(getattr(args, "json", False)))


def table_console(stderr: bool) -> Console:
    """Console whose tables keep their natural width off a terminal (a pipe, a file, a CI log)
    instead of being squeezed into 80 columns; a terminal's own width otherwise."""
    probe = Console(stderr=stderr)
    width = None if probe.is_terminal else OFF_TERMINAL_WIDTH
    return Console(stderr=stderr, highlight=False, soft_wrap=True, width=width)


def json_safe(obj: Any) -> Any:
    """Make numpy scalars/arrays and non-finite floats JSON-safe."""
    if isinstance(obj, dict):
        return {str(k): json_safe(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [json_safe(v) for v in obj]
    if hasattr(obj, "tolist"):
        return json_safe(obj.tolist())
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj


def emit(args, result: dict, human: str | None = None) -> None:
    """Report a command's figures: JSON to stdout (with --json) and/or human text."""
    if human:
        human_console(args).print(human)
    if getattr(args, "json", False):
        sys.stdout.write(json.dumps(json_safe(result), sort_keys=False) + "\n")
        sys.stdout.flush()


@contextmanager
def progress(args, description: str, total: int | None):
    """A rich progress bar on stderr (silent with -q, and when stderr is not a terminal);
    yields ``advance(n=1, total=None)`` (``total`` re-sets the bar's length)."""
    quiet = getattr(args, "verbose", 0) < 0
    console = Console(stderr=True)
    bar = Progress(TextColumn("[bold]{task.description}"), BarColumn(), MofNCompleteColumn(),
                   TimeRemainingColumn(), console=console, transient=True,
                   disable=quiet or not console.is_terminal)
    with bar:
        task = bar.add_task(description, total=total)

        def advance(n=1, total=None):
            if total is not None:
                bar.update(task, total=total)
            bar.advance(task, n)

        yield advance


def emit_error(as_json: bool, message: str, exit_code: int) -> None:
    """With --json: the error object ``{"error": message, "exit_code": N}`` on stdout."""
    if as_json:
        sys.stdout.write(json.dumps({"error": message, "exit_code": int(exit_code)}) + "\n")
        sys.stdout.flush()


def write_or_print(text: str, argv: list[str]) -> int:
    """A generator's ``main``: ``text`` to the file named by ``argv[0]``, or to stdout."""
    if argv:
        with open(argv[0], "w") as fh:
            fh.write(text)
    else:
        sys.stdout.write(text)
    return 0
