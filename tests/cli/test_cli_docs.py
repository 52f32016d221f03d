"""The callback example of docs/FLATSAT.md runs as written on a fresh checkout."""

import re

from gyrostar.paths import repo_root


def _block(heading: str) -> str:
    text = (repo_root() / "docs" / "FLATSAT.md").read_text()
    section = text.split(heading, 1)[1]
    return re.search(r"```python\n(.*?)```", section, re.S).group(1)


def test_flatsat_callback_example(tmp_path, monkeypatch, capsys):
    runs = tmp_path / "runs"                   # not there yet: the example must create it
    monkeypatch.setenv("GYROSTAR_RUNS", str(runs))
    monkeypatch.chdir(tmp_path)
    scope: dict = {}
    exec(compile(_block("### Callback (in-process)"), "FLATSAT.md", "exec"), scope)
    folder, summary, last = scope["folder"], scope["summary"], scope["last"]
    assert folder.parent == runs and (folder / "flatsat.gslog").stat().st_size > 0
    assert (folder / "summary.json").exists()
    assert summary["gyro_samples"] > 0 and abs(float((last["q"] ** 2).sum()) - 1.0) < 1e-9
    assert "frames; last output at" in capsys.readouterr().out

