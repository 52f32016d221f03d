"""Where gyrostar keeps caches and run folders.

Caches (catalog arrays, star-pair indexes, numba) go under ``$GYROSTAR_CACHE`` or
``$XDG_CACHE_HOME/gyrostar`` (``~/.cache/gyrostar``); run outputs under ``$GYROSTAR_RUNS`` or ``./runs``.
"""

import os
from pathlib import Path

from .errors import ConfigError


def cache_root() -> Path:
    """The cache folder: ``$GYROSTAR_CACHE``, else ``$XDG_CACHE_HOME/gyrostar``, else
    ``~/.cache/gyrostar`` (numba's compiled kernels go under it too: gyrostar/__init__.py)."""
    if os.environ.get("GYROSTAR_CACHE"):
        return Path(os.environ["GYROSTAR_CACHE"])
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "gyrostar"


def _unusable(path: Path, exc: OSError) -> ConfigError:
    given = "GYROSTAR_CACHE" in os.environ and os.environ["GYROSTAR_CACHE"]
    return ConfigError(f"cache folder {path} is not writable ({exc.strerror or exc}): "
                       + ("set GYROSTAR_CACHE to a writable folder" if not given
                          else "GYROSTAR_CACHE must name a writable folder"))


def cache_dir(*parts: str) -> Path:
    """Return (and create) a cache sub-folder (:class:`ConfigError` naming it when it cannot be made)."""
    path = cache_root().joinpath(*parts)
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise _unusable(path, exc) from None
    return path


def check_cache_writable() -> Path:
    """The cache folder, after writing a file in it: a command that compiles kernels and builds
    the star index checks this first (exit 2 naming it), not after a minute of compiling."""
    import tempfile

    root = cache_dir()
    try:
        with tempfile.NamedTemporaryFile(dir=root, prefix=".write-test-"):
            pass
    except OSError as exc:
        raise _unusable(root, exc) from None
    return root


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
