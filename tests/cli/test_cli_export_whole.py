"""An export is written whole or not at all: one cut short (Ctrl-C, a full disk) leaves no
file at ``--out`` that looks valid (it left 4,299 of 11,996 CSV lines and no metadata, which a
rerun then refused to overwrite), and the next export to the same path just works."""

import json

import numpy as np
import pytest
from gyrostar.hil import replay
from gyrostar.loop.record import OUTPUT_DTYPE
from gyrostar.recording import logfile as lf

N = 500


@pytest.fixture
def log(tmp_path):
    """A small flatsat log: META, N outputs, the closing summary."""
    out = np.zeros(N, OUTPUT_DTYPE)
    out["t"] = 100.0 + np.arange(N) / 400.0
    out["seq"] = np.arange(N)
    out["q"] = [0.0, 0.0, 0.0, 1.0]
    path = tmp_path / "flatsat.gslog"
    with lf.LogWriter(path) as w:
        w.meta({"format": "gyrostar flatsat log 1", "scenario": {"name": "t"}})
        w.append_rows(lf.OUTPUT, out)
        w.event({"summary": {}})
    return path


class _CutFile:
    """A text file whose ``write`` raises ``exc`` at call ``at`` (a Ctrl-C or a full disk mid-export)."""

    def __init__(self, fh, at, exc):
        self.fh, self.at, self.exc, self.n = fh, at, exc, 0

    def write(self, text):
        self.n += 1
        if self.n == self.at:
            raise self.exc
        return self.fh.write(text)

    def __enter__(self):
        return self

    def __exit__(self, *a):
        self.fh.close()


@pytest.mark.parametrize("exc", [KeyboardInterrupt(), OSError(28, "No space left on device")],
                         ids=["ctrl-c", "disk-full"])
def test_cut_csv_export_leaves_nothing_and_a_rerun_writes_it_whole(log, tmp_path, monkeypatch, exc):
    out = tmp_path / "x.csv"
    real_open = open
    monkeypatch.setattr(replay, "open", lambda p, mode="r", *a, **k: _CutFile(real_open(p, mode, *a, **k), N // 2,
                                                                               exc), raising=False)
    with pytest.raises((KeyboardInterrupt, replay.ConfigError)):
        replay.export(log, "csv", out)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["flatsat.gslog"]      # no CSV, no partial file
    monkeypatch.undo()
    res = replay.export(log, "csv", out)                        # no --force needed: nothing was left
    lines = out.read_text().splitlines()
    assert res["outputs"] == N and len(lines) == N + 1
    meta = json.loads((tmp_path / "x.csv-metadata.json").read_text())
    assert meta["url"] == "x.csv"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["flatsat.gslog", "x.csv", "x.csv-metadata.json"]


def test_cut_hdf5_export_leaves_nothing(log, tmp_path, monkeypatch):
    out = tmp_path / "x.h5"

    def cut(recs, truth, meta, part):
        part.write_bytes(b"\x89HDF\r\n\x1a\n half a file")
        raise KeyboardInterrupt

    monkeypatch.setattr(replay, "_export_hdf5", cut)
    with pytest.raises(KeyboardInterrupt):
        replay.export(log, "hdf5", out)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["flatsat.gslog"]
