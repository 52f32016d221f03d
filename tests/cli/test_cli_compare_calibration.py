"""``gyrostar replay LOG --compare-calibration CAL``: the comparison with the simulator's truth,
read by a person without --json (it printed raw JSON), one object with it."""

import json

import pytest
from cli_helpers import gyrostar


@pytest.fixture(scope="module")
def miscal_log(tmp_path_factory):
    out = tmp_path_factory.mktemp("run") / "r"
    res = gyrostar(["run", "--fast", "--scenario", "miscal", "--duration", "2", "--no-plots", "-q", "--out", out],
                   timeout=600)
    assert res.returncode in (0, 1), res.stderr
    return out / "flatsat.gslog"


def _true_camera_toml(path):
    from gyrostar.calibration import calfile
    from gyrostar.camera import camera_preset
    from gyrostar.hil import config as hc
    from gyrostar.hil.flatsat import true_camera

    cam = true_camera(camera_preset("xing2012"), hc.load_scenario("miscal").truth)
    cal = calfile.CameraCal(cam.focal_length_px, (cam.cx_px, cam.cy_px), cam.k1, cam.k2, cam.k3, cam.p1, cam.p2,
                            image_size_px=(cam.width_px, cam.height_px), residual_rms_px=0.02,
                            principal_point_sigma_px=(0.1, 0.1))
    calfile.write_section(path, "camera", cal, source="the scenario's truth")
    return cam


def test_comparison_is_text_without_json_and_an_object_with_it(miscal_log, tmp_path):
    cam = _true_camera_toml(tmp_path / "cal.toml")
    res = gyrostar(["replay", miscal_log, "--compare-calibration", tmp_path / "cal.toml"])
    assert res.returncode == 0, res.stderr
    with pytest.raises(json.JSONDecodeError):
        json.loads(res.stdout)
    assert "against the simulator truth" in res.stdout
    assert f"focal length {cam.focal_length_px:.2f} px (true {cam.focal_length_px:.2f}, +0.0000 %)" in res.stdout
    assert "0.00 px off" in res.stdout and "time offset" in res.stdout
    obj = json.loads(gyrostar(["replay", miscal_log, "--compare-calibration", tmp_path / "cal.toml", "--json"]).stdout)
    assert obj["camera"]["principal_point_error_px"] == pytest.approx(0.0, abs=1e-9)
    assert obj["camera"]["k1_true"] == pytest.approx(0.3)
