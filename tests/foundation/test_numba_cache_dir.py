"""numba's cache folder follows the package's sources (a stale callee is never reused)."""

import os
import subprocess
import sys


def _cache_dir(env):
    out = subprocess.run([sys.executable, "-c", "import gyrostar, os; print(os.environ['NUMBA_CACHE_DIR'])"],
                         env=env, capture_output=True, text=True, check=True)
    return out.stdout.strip()


def test_cache_folder_is_named_after_the_sources_and_an_explicit_setting_wins(tmp_path):
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"} | {"XDG_CACHE_HOME": str(tmp_path)}
    a = _cache_dir(env)
    assert a.startswith(str(tmp_path / "gyrostar" / "numba")) and os.path.isdir(a)
    assert _cache_dir(env) == a                                  # same sources, same folder
    assert _cache_dir(env | {"NUMBA_CACHE_DIR": str(tmp_path / "mine")}) == str(tmp_path / "mine")
