"""The numba cache key covers the modules compiled code can depend on, and only those."""

from pathlib import Path

from gyrostar.kernel_sources import kernel_closure, kernel_sources_key, package_modules

ROOT = Path(__file__).resolve().parents[2]
ROOTS = [("gyrostar", ROOT / "driver"), ("gyrostar.mocks", ROOT / "mocks"), ("gyrostar.hil", ROOT / "hil")]


def _write(root: Path, files: dict[str, str]) -> None:
    for rel, text in files.items():
        p = root / rel
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text(text)


def _fake_package(tmp_path: Path) -> list[tuple[str, Path]]:
    _write(tmp_path / "pkg", {
        "__init__.py": "",
        "kern.py": ("from numba import njit\nfrom .consts import SCALE\n"
                    "from . import (  # the tables\n    tables as T,\n)\n"),
        "consts.py": "from .sub.deep import BASE\nSCALE = 2 * BASE\n",
        "tables.py": "X = 1\n",
        "sub/__init__.py": "",
        "sub/deep.py": "BASE = 3\n",
        "sub/other.py": "import gyrostar_fake.kern2\n",
        "cli.py": "from .kern import SCALE\nfrom .plots import draw\n",
        "plots.py": "def draw():\n    pass\n",
        "test_kern.py": "import numba\n",
    })
    _write(tmp_path / "side", {
        "__init__.py": "",
        "render.py": "import numba\nfrom ..consts import SCALE\nfrom pkg.sub import (\n    deep,  # the base\n)\n",
        "runner.py": "from .render import X\n",
    })
    return [("pkg", tmp_path / "pkg"), ("pkg.side", tmp_path / "side")]


def test_closure_follows_relative_absolute_and_parenthesised_imports(tmp_path):
    mods = package_modules(_fake_package(tmp_path))
    assert "pkg.test_kern" not in mods                      # tests hold no kernels
    assert kernel_closure(mods) == ["pkg", "pkg.consts", "pkg.kern", "pkg.side", "pkg.side.render", "pkg.sub",
                                    "pkg.sub.deep", "pkg.tables"]


def test_key_changes_with_a_dependency_of_a_kernel_and_not_with_other_modules(tmp_path):
    roots = _fake_package(tmp_path)
    key = kernel_sources_key(roots)
    assert kernel_sources_key(roots) == key
    for rel in ("pkg/cli.py", "pkg/plots.py", "side/runner.py", "pkg/sub/other.py"):
        p = tmp_path / rel
        p.write_text(p.read_text() + "# edited\n")
        assert kernel_sources_key(roots) == key, rel
    deep = tmp_path / "pkg/sub/deep.py"                      # two imports away from the kernel
    deep.write_text("BASE = 4\n")
    assert kernel_sources_key(roots) != key


def test_the_package_closure_holds_its_kernels_and_their_constants_and_not_the_front_ends():
    closure = set(kernel_closure(package_modules(ROOTS)))
    for name in ("gyrostar.loop.kernels", "gyrostar.loop.frame_kernel", "gyrostar.core.mekf",
                 "gyrostar.mocks.render", "gyrostar.mocks.pixel_noise", "gyrostar.starid.pyramid",
                 "gyrostar.loop.record", "gyrostar.protocol.payloads"):
        assert name in closure, name
    for name in ("gyrostar.cli.main", "gyrostar.hil.runner", "gyrostar.hil.plots", "gyrostar.loop.coupled"):
        assert name not in closure, name
