"""Logging set-up for the CLI: one stdlib logger per module, level from -v/-q."""

import logging

from rich.logging import RichHandler


def setup(verbosity: int) -> None:
    """verbosity: -1 quiet (errors), 0 warnings, 1 info, 2+ debug. Logs go to stderr."""
    level = {-1: logging.ERROR, 0: logging.WARNING, 1: logging.INFO}.get(verbosity, logging.DEBUG)
    from rich.console import Console

    logging.basicConfig(
        level=level,
        format="%(name)s: %(message)s",
        handlers=[RichHandler(console=Console(stderr=True), show_path=False, show_time=False)],
        force=True,
    )
