"""The three folders map onto one import tree, editable and from a built wheel."""

import subprocess
import sys
import zipfile
from pathlib import Path

import gyrostar
import gyrostar.hil
import gyrostar.mocks
import pytest

REPO = Path(__file__).resolve().parents[2]


def test_editable_install_maps_folders():
    assert Path(gyrostar.__file__).resolve().parent == REPO / "driver"
    assert Path(gyrostar.mocks.__file__).resolve().parent == REPO / "mocks"
    assert Path(gyrostar.hil.__file__).resolve().parent == REPO / "hil"


@pytest.mark.timeout(600)
def test_built_wheel_imports(tmp_path):
    res = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation",
                          "-q", "-w", str(tmp_path), str(REPO)], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    wheel = next(tmp_path.glob("gyrostar-*.whl"))
    names = zipfile.ZipFile(wheel).namelist()
    for init in ("gyrostar/__init__.py", "gyrostar/mocks/__init__.py", "gyrostar/hil/__init__.py",
                 "gyrostar/cli/main.py", "gyrostar/attitude.py"):
        assert init in names
    assert not any(n.startswith(("driver/", "mocks/", "hil/")) for n in names)
    target = tmp_path / "site"
    subprocess.run([sys.executable, "-m", "pip", "install", "-q", "--no-deps", "--target", str(target),
                    str(wheel)], check=True)
    # -S: no site-packages, so the editable finder cannot shadow the wheel's copy
    code = (f"import sys; sys.path.insert(0, {str(target)!r}); import gyrostar, gyrostar.mocks, gyrostar.hil; "
            "print(gyrostar.__file__); print(gyrostar.mocks.__file__); print(gyrostar.hil.__file__)")
    out = subprocess.run([sys.executable, "-S", "-c", code], capture_output=True, text=True, check=True)
    paths = out.stdout.split()
    assert len(paths) == 3 and all(p.startswith(str(target)) for p in paths)
