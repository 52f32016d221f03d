"""docs/CONFIG.md is generated from the config schema and kept current; every key is in it."""

import dataclasses

from gyrostar.hil import config as hc
from gyrostar.hil.config_doc import render


def test_config_reference_is_current_and_complete(repo):
    text = render()
    assert (repo / "docs" / "CONFIG.md").read_text() == text, "run make config-doc"
    for cls, prefix in ((hc.HeadConfig, "head."), (hc.GyroConfig, "gyro."), (hc.OutputsConfig, "outputs."),
                        (hc.LoopConfig, "loop."), (hc.TrueDevices, "truth.")):
        for f in dataclasses.fields(cls):
            row = next((ln for ln in text.splitlines() if ln.startswith(f"| `{prefix}{f.name}`")), None)
            assert row is not None, f"{prefix}{f.name}"
            assert not row.endswith("|  |"), f"{prefix}{f.name} has no meaning"


def test_relative_calibration_path_is_taken_from_the_config_folder(tmp_path, monkeypatch):
    from gyrostar.hil.config import default_config_path, load_flatsat

    bench = tmp_path / "bench"
    bench.mkdir()
    text = default_config_path().read_text().replace('calibration = ""', 'calibration = "cal/head.toml"')
    (bench / "flatsat.toml").write_text(text)
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    assert load_flatsat(bench / "flatsat.toml").calibration == str(bench / "cal" / "head.toml")
    (bench / "abs.toml").write_text(text.replace('"cal/head.toml"', '"/srv/cal.toml"'))
    assert load_flatsat(bench / "abs.toml").calibration == "/srv/cal.toml"
    assert load_flatsat().calibration == ""                          # none given: none resolved
