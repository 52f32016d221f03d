"""``gyrostar eval starid|centroid``: bad arguments are refused before any work (exit 2, one
line naming the flag, no traceback), and every identifier method runs."""

import json
import subprocess
import sys

import pytest


def _gyrostar(cwd, *args):
    return subprocess.run([sys.executable, "-m", "gyrostar", *args], capture_output=True, text=True, timeout=300,
                          cwd=cwd)


@pytest.mark.parametrize("args, flag", [
    (["--sweep", "fig10", "--plot", "plainfile"], "--plot"),
    (["--sweep", "fig10", "--plot", "plainfile/x.png"], "--plot"),
    (["--plot", "x.png"], "--plot"),
    (["--sweep", "all", "--plot", "x.png"], "--plot"),
    (["--preset", "foo"], "--preset"),
    (["--mag-limit", "nan"], "--mag-limit"),
    (["--fov-deg", "45"], "--fov-deg"),
    (["--fov-deg", "0.001"], "--fov-deg"),
    (["--pixels", "512"], "--pixels"),
    (["--peer", "tetra3rs"], "--peer"),
    (["--workers", "0"], "--workers"),
])
def test_eval_starid_refuses_bad_arguments_at_once(tmp_path, args, flag):
    (tmp_path / "plainfile").write_text("keep")
    proc = _gyrostar(tmp_path, "eval", "starid", *args, "--trials", "5", "--json")
    assert proc.returncode == 2, proc.stderr
    assert flag in proc.stderr and "Traceback" not in proc.stderr and len(proc.stderr.strip().splitlines()) == 1
    assert (tmp_path / "plainfile").read_text() == "keep"


@pytest.mark.parametrize("args, flag", [
    (["--plot", "existing.txt"], "--plot"),
    (["--plot", "nodir/c.png"], "--plot"),
    (["--gyro-noise-dps-rthz=-1"], "--gyro-noise-dps-rthz"),
    (["--gyro-noise-dps-rthz=nan"], "--gyro-noise-dps-rthz"),
    (["--gyro-noise-dps-rthz=1e9"], "--gyro-noise-dps-rthz"),
])
def test_eval_centroid_refuses_bad_arguments(tmp_path, args, flag):
    (tmp_path / "existing.txt").write_text("keep")
    proc = _gyrostar(tmp_path, "eval", "centroid", *args, "--json")
    assert proc.returncode == 2 and flag in proc.stderr and "Traceback" not in proc.stderr
    assert (tmp_path / "existing.txt").read_text() == "keep"


def test_eval_starid_grid_method_runs(tmp_path):
    """The lost-in-space grid baseline takes positions only (it was given magnitudes and failed)."""
    proc = _gyrostar(tmp_path, "eval", "-q", "starid", "--method", "grid", "--trials", "20", "--workers", "1",
                     "--seed", "3", "--json")
    assert proc.returncode == 0, proc.stderr
    out = json.loads(proc.stdout)
    assert out["trials"] == 20 and out["success_rate"] > 0.5 and out["false_ids"] == 0
