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


def test_driver_helpers_apply_the_calibration(tmp_path):
    import numpy as np
    from gyrostar.camera import camera_preset

    path = tmp_path / "cal.toml"
    nominal = camera_preset("xing2012")
    calfile.write_section(path, "camera", calfile.CameraCal(6700.0, (515.0, 509.0), k1=0.3), source="t")
    corr = ((1.001, 0.0, 0.0), (0.0, 0.999, 0.0), (0.0, 0.0, 1.0))
    calfile.write_section(path, "gyro_scale", calfile.GyroScaleCal(corr, corr, (0.01, 0.0, 0.0), (0.0,) * 3), "t")
    q = (0.0, 0.0, np.sin(np.pi / 4), np.cos(np.pi / 4))  # 90° about z
    calfile.write_section(path, "alignment", calfile.AlignmentCal(q, -0.002), source="t")
    cal = calfile.load(path)
    cam = calfile.camera_model(cal, nominal)
    assert cam.focal_length_px == pytest.approx(6700.0) and (cam.cx_px, cam.k1) == (515.0, 0.3)
    m, b, dt = calfile.gyro_to_camera(cal)
    w = m @ (np.array([1.0, 0.0, 0.0]) - b)
    # x gyro axis scaled by 1.001 after bias removal, then turned 90° about z (A(q) convention)
    np.testing.assert_allclose(np.abs(w), [0.0, 0.99 * 1.001, 0.0], atol=1e-12)
    assert dt == -0.002


def test_hot_pixel_mask(tmp_path):
    path = tmp_path / "cal.toml"
    calfile.write_section(path, "dark", calfile.DarkCal("d.fits", 3.0, 100.0, 20.0, [(5, 2), (0, 7)]), source="t")
    mask = calfile.hot_pixel_mask(calfile.load(path), 8, 8)
    assert mask.sum() == 2 and mask[2, 5] and mask[7, 0]
    with pytest.raises(ConfigError):
        calfile.hot_pixel_mask(calfile.load(path), 4, 4)


def test_report_that_is_a_file_is_refused_and_kept(tmp_path):
    keep = tmp_path / "existing.txt"
    keep.write_text("keep")
    assert main(["calibrate", "dark", "--simulate", "--report", str(keep)]) == 2
    assert keep.read_text() == "keep"
