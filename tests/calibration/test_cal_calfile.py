"""Calibration TOML: sections merge, load back through gyrostar.config, and reject bad input."""

import pytest
from gyrostar.calibration import calfile
from gyrostar.cli.main import main
from gyrostar.errors import ConfigError


def test_sections_merge_and_load(tmp_path):
    path = tmp_path / "cal.toml"
    cam = calfile.CameraCal(6700.0, (511.0, 512.5), k1=0.3)
    calfile.write_section(path, "camera", cam, source="test")
    al = calfile.AlignmentCal((0.0, 0.0, 0.0, 1.0), 0.0025)
    calfile.write_section(path, "alignment", al, source="test")
    cal = calfile.load(path)
    assert cal.camera.focal_length_px == 6700.0 and cal.camera.principal_point_px == (511.0, 512.5)
    assert cal.alignment.time_offset_s == 0.0025
    assert set(cal.meta.updated) == {"camera", "alignment"}


def test_bad_values_and_keys_are_rejected_without_losing_the_file(tmp_path):
    path = tmp_path / "cal.toml"
    calfile.write_section(path, "camera", calfile.CameraCal(6700.0, (511.0, 512.5)), source="test")
    before = path.read_text()
    with pytest.raises(ConfigError):
        calfile.write_section(path, "alignment", calfile.AlignmentCal((0.0, 0.0, 0.5, 0.5), 0.0), source="x")
    assert path.read_text() == before
    path.write_text(before + "\n[bogus]\nx = 1\n")
    with pytest.raises(ConfigError, match="bogus"):
        calfile.load(path)


def test_cli_needs_exactly_one_source(tmp_path):
    assert main(["calibrate", "camera", "--report", str(tmp_path)]) == 2
    assert main(["calibrate", "dark", str(tmp_path / "missing.npz"), "--report", str(tmp_path)]) == 2
