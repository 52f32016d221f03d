"""A run whose disk fills: one line naming the log with the documented ``write failed after N
bytes``, exit 3, and no 0-byte summary.json or PNG left (a 1 MB tmpfs; skipped where it cannot
be mounted)."""

import json

import pytest
from cli_helpers import gyrostar, tmpfs


@pytest.fixture
def small_disk(tmp_path):
    with tmpfs(tmp_path / "disk", "size=1m", "a full disk needs a small tmpfs mount (root)") as disk:
        yield disk


def test_full_disk_names_the_log_and_leaves_no_empty_files(small_disk, tmp_path):
    out = small_disk / "run"
    res = gyrostar(["run", "--fast", "--duration", "5", "--out", out], cwd=tmp_path, timeout=600)
    lines = [ln for ln in res.stderr.splitlines() if ln.strip()]
    assert res.returncode == 3, res.stderr
    assert "Traceback" not in res.stderr
    errors = [ln for ln in lines if "ERROR" in ln]
    assert len(errors) == 1, res.stderr
    assert f"log {out / 'flatsat.gslog'}: write failed after " in errors[0] and "No space left" in errors[0]
    left = {p.name: p.stat().st_size for p in out.iterdir()}
    assert left["flatsat.gslog"] > 0
    assert not [n for n, size in left.items() if size == 0], left          # no 0-byte summary or PNG
    assert not [n for n in left if ".partial-" in n], left
    if "summary.json" in left:
        assert "write failed after" in json.loads((out / "summary.json").read_text())["log_error"]
