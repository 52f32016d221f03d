"""Calibration files with bad bytes or values: refused at load with one ConfigError (exit 2)
naming the file and the dotted key, before anything reaches the loop; good files still load."""

import math

import numpy as np
import pytest
from gyrostar.calibration import apply, calfile
from gyrostar.camera import camera_preset
from gyrostar.cli.main import main
from gyrostar.errors import ConfigError

CAMERA = ("[camera]\nfocal_length_px = {f}\nprincipal_point_px = [{cx}, {cy}]\n"
          "image_size_px = [1024, 1024]\n")
ALIGN = "[alignment]\nq_gyro_to_camera = [{q}]\ntime_offset_s = {dt}\n"


def _cal(tmp_path, text: str):
    p = tmp_path / "cal.toml"
    p.write_text(text)
    return p


def _camera(f="6666.7", cx="511.5", cy="511.5"):
    return CAMERA.format(f=f, cx=cx, cy=cy)


def _align(q="0.0, 0.0, 0.0, 1.0", dt="0.002"):
    return ALIGN.format(q=q, dt=dt)


@pytest.mark.parametrize("text,expected", [
    # a missing / ill-typed / out-of-range key inside an optional table names the key, not the table
    ("[camera]\nprincipal_point_px = [511.5, 511.5]\n", "missing required key 'camera.focal_length_px'"),
    (_camera(f="-5.0"), "camera.focal_length_px must be > 0, got -5.0"),
    (_camera(f='"big"'), "key 'camera.focal_length_px' expects a number, got string"),
    (_camera(f="nan"), "key 'camera.focal_length_px' must be a finite number"),
    (_camera() + "focal = 3\n", "unknown key 'camera.focal'"),
    ("[gyro_scale]\ncorrection = \"x\"\nsensitivity = \"x\"\nbias_rps = [0, 0, 0]\nscale_factor_ppm = [0, 0, 0]\n",
     "key 'gyro_scale.correction' expects an array of 3 items, got string"),
    # physical bounds
    (_camera(f="100"), "camera.focal_length_px = 100 gives a 164° diagonal field of view"),
    (_camera(f="1e7"), "camera.focal_length_px = 1e+07 gives a 0.0083° diagonal field of view"),
    (_camera(cx="-3000", cy="4000"), "camera.principal_point_px (-3000, 4000) is off the 1024×1024 px sensor"),
    (_camera() + "k1 = 1e6\n", "camera.k1, k2, k3 distort the sensor corner"),
    (_camera() + "principal_point_sigma_px = [0.05, -0.1]\n", "camera.principal_point_sigma_px must be two values in "
     "[0, 100] px, got [0.05, -0.1]"),
    (_camera() + "principal_point_sigma_px = [0.05]\n", "key 'camera.principal_point_sigma_px' must have 2 items"),
    (_align(dt="1e9"), "alignment.time_offset_s must be within ±1 s, got 1000000000.0"),
    (_align(dt="-1.5"), "alignment.time_offset_s must be within ±1 s"),
    (_align(q="0.0, 0.0, 0.5, 0.5"), "alignment.q_gyro_to_camera must be a unit quaternion"),
    (_align(q="0.0, 0.0, 0.0, 0.0"), "alignment.q_gyro_to_camera must be a unit quaternion"),
    (_align(q="0.0, 0.0, 1.0"), "key 'alignment.q_gyro_to_camera' must have 4 items, got 3"),
    (_align(q="0.0, 0.0, nan, 1.0"), "key 'alignment.q_gyro_to_camera[2]' must be a finite number"),
    ("[gyro_static]\nbias_rps = [0.5, 0, 0]\narw_rad_per_sqrt_s = [0, 0, 0]\nbias_instability_rps = [0, 0, 0]\n"
     "rrw_rps_per_sqrt_s = [0, 0, 0]\n", "gyro_static.bias_rps must be within"),
])
def test_bad_calibration_value_names_key_and_file(tmp_path, text, expected):
    p = _cal(tmp_path, text)
    for load in (calfile.load, apply.load_for_run):
        with pytest.raises(ConfigError) as err:
            load(p)
        msg = str(err.value)
        assert msg.startswith(f"{p}: ") and expected in msg, msg
        assert "expects a table" not in msg and "\n" not in msg


def test_bounds_admit_real_calibrations(tmp_path):
    """The nominal camera, a principal point at a sensor corner, a hand-typed quaternion
    (norm 1 within 1e-3, normalised when applied) and a 1 s offset load."""
    nom = camera_preset("xing2012")
    q = "0.0, 0.0, 0.7071, 0.7071"                # 90° about z, norm 0.99999 (4 decimals)
    p = _cal(tmp_path, _camera(f=repr(nom.focal_length_px), cx="0", cy="1023") + _align(q=q, dt="-1.0"))
    cal = calfile.load(p)
    assert cal.camera.principal_point_px == (0.0, 1023.0) and cal.alignment.time_offset_s == -1.0
    m, _, _ = calfile.gyro_to_camera(cal)
    # a rotation (unnormalised, A(q) would be 0.99998 × one): 90° about z, passive form
    np.testing.assert_allclose(m, [[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]], atol=1e-12)
    fov = 2.0 * math.degrees(math.atan(0.5 * math.hypot(1024, 1024) / nom.focal_length_px))
    assert calfile.FOV_DEG[0] < fov < calfile.FOV_DEG[1]


def test_non_utf8_calibration_file(tmp_path):
    p = tmp_path / "bin.toml"
    p.write_bytes(b"\xff\xfe[camera]\n")
    for load in (calfile.load, apply.load_for_run):
        with pytest.raises(ConfigError, match=f"{p} is not UTF-8 text TOML"):
            load(p)


@pytest.mark.parametrize("content", [
    b"\xff\xfe\x00binary",                      # not text
    b"GSLOG\x00\x01\x02\x80\x81",               # a binary log
    b'name = "flatsat"\n[loop]\nframe_hz = 10\n',   # another TOML (a flatsat config)
    b"# my notes\nnot = [toml\n",               # text that is not TOML
])
def test_write_section_never_overwrites_a_foreign_file(tmp_path, content):
    p = tmp_path / "out.toml"
    p.write_bytes(content)
    cam = calfile.CameraCal(6700.0, (511.0, 512.5))
    with pytest.raises(ConfigError, match=f"{p} exists and is not a calibration file; left as it is"):
        calfile.write_section(p, "camera", cam, source="test")
    assert p.read_bytes() == content and not p.with_name("out.toml.tmp").exists()


def test_write_section_replaces_a_bad_table_of_a_calibration_file(tmp_path):
    """An existing calibration file whose table is out of bounds can be recalibrated; a bad
    table that is kept is reported by its key."""
    p = _cal(tmp_path, _camera(f="100") + _align())
    calfile.write_section(p, "camera", calfile.CameraCal(6700.0, (511.0, 512.5)), source="test")
    cal = calfile.load(p)
    assert cal.camera.focal_length_px == 6700.0 and cal.alignment.time_offset_s == 0.002
    p.write_text(_camera() + _align(dt="1e9"))
    before = p.read_text()
    with pytest.raises(ConfigError, match="alignment.time_offset_s"):
        calfile.write_section(p, "camera", calfile.CameraCal(6700.0, (511.0, 512.5)), source="test")
    assert p.read_text() == before


@pytest.mark.parametrize("argv", [
    ["run", "--fast", "--duration", "1", "--calibration", "{bin}"],
    ["run", "--fast", "--duration", "1", "--config", "{bin}"],
    ["run", "--fast", "--duration", "1", "--scenario", "{bin}"],
    ["run", "--fast", "--duration", "1", "--calibration", "{big_offset}"],
    ["run", "--fast", "--duration", "1", "--calibration", "{short_focal}"],
])
def test_cli_refuses_bad_files_with_exit_2(tmp_path, capsys, argv):
    files = {"bin": tmp_path / "bin.toml", "big_offset": tmp_path / "o.toml", "short_focal": tmp_path / "f.toml"}
    files["bin"].write_bytes(b"\xff\xfe[a]\n")
    files["big_offset"].write_text(_align(dt="1e9"))
    files["short_focal"].write_text(_camera(f="100"))
    argv = [a.format(**{k: str(v) for k, v in files.items()}) for a in argv] + ["--out", str(tmp_path / "run")]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "internal error" not in err and "Traceback" not in err
    name = next(str(v) for v in files.values() if str(v) in argv)
    assert name in err, err
    assert ("UTF-8" in err) or ("time_offset_s" in err) or ("focal_length_px" in err and "field of view" in err)


def test_calibrate_refuses_a_foreign_out_before_its_fit(tmp_path):
    """--out naming a file that is not a calibration file (or a folder) is a usage error at
    parse time, before any fit runs; the file is left as it was."""
    import argparse

    from gyrostar.calibration.report import calibration_out

    foreign = tmp_path / "flatsat.toml"
    foreign.write_text("[loop]\nframe_hz = 100\n")
    for bad, words in ((foreign, "not a calibration file"), (tmp_path, "is a folder")):
        with pytest.raises(argparse.ArgumentTypeError, match=words):
            calibration_out(str(bad))
    assert foreign.read_text() == "[loop]\nframe_hz = 100\n"
    assert calibration_out(str(tmp_path / "new.toml")) == tmp_path / "new.toml"
