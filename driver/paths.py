"""Where gyrostar keeps caches and run folders.

Caches (catalog arrays, star-pair indexes, numba) go under ``$GYROSTAR_CACHE`` or
``~/.cache/gyrostar``; run outputs under ``$GYROSTAR_RUNS`` or ``./runs``.
"""

import os
from pathlib import Path

from .errors import ConfigError


def cache_dir(*parts: str) -> Path:
    """Return (and create) a cache sub-folder."""
    root = Path(os.environ.get("GYROSTAR_CACHE", Path.home() / ".cache" / "gyrostar"))
    path = root.joinpath(*parts)
    path.mkdir(parents=True, exist_ok=True)
    return path


def runs_dir() -> Path:
    """Return (and create) the folder that holds one sub-folder per run."""
    given = os.environ.get("GYROSTAR_RUNS")
    path = Path(given or "runs")
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        where = f"GYROSTAR_RUNS={given}" if given else f"the default run folder {path.resolve()}"
        raise ConfigError(f"{where}: cannot be used as the runs folder ({exc.strerror or exc})") from None
    return path


def repo_root() -> Path | None:
    """The source checkout this package was installed from (editable), if any."""
    here = Path(__file__).resolve().parent.parent
    return here if (here / "pyproject.toml").is_file() and (here / "driver").is_dir() else None
