"""Camera model: projection against hand-computed pixels, round trips, presets."""

import math

import numpy as np
import pytest
from gyrostar.camera import CameraModel, camera_preset, project_point, unproject_point
from gyrostar.errors import ConfigError


def test_xing2012_pinhole_hand_values():
    cam = camera_preset("xing2012")
    assert cam.focal_length_px == pytest.approx(100e-3 / 15e-6)
    # a star 1 mrad off-axis along +x lands F*tan/pitch = 6.6667 px right of centre
    ang = 1e-3
    uv, ok = cam.project(np.array([[math.sin(ang), 0.0, math.cos(ang)]]))
    assert ok[0]
    assert uv[0, 0] == pytest.approx(511.5 + 6666.6667 * math.tan(ang), abs=1e-6)
    assert uv[0, 1] == pytest.approx(511.5, abs=1e-9)
    # +y goes down the rows
    uv, _ = cam.project(np.array([[0.0, 0.01, 1.0]]))
    assert uv[0, 1] == pytest.approx(511.5 + 66.666667, abs=1e-5)
    # FOV: 1024 px * 15 um over 100 mm -> 2*atan(7.68/100)
    assert cam.fov_x_deg == pytest.approx(2 * math.degrees(math.atan(7.68e-3 / 0.1)), rel=1e-9)


def test_qian2015_scale_is_28_1_arcsec_per_px():
    cam = camera_preset("qian2015")
    assert cam.fov_x_deg == pytest.approx(4.0, abs=1e-9)
    assert cam.fov_y_deg == pytest.approx(4.0, abs=1e-9)
    assert math.degrees(cam.ifov_rad) * 3600 == pytest.approx(28.1, abs=0.05)


def test_behind_and_off_sensor_invalid():
    cam = camera_preset("xing2012")
    _, ok = cam.project(np.array([[0, 0, -1.0], [0.2, 0, 1.0], [0, 0, 1.0]]))
    assert ok.tolist() == [False, False, True]


@pytest.mark.parametrize("dist", [(0, 0, 0, 0, 0), (-0.3, 0.1, 0.02, 1e-3, -2e-3), (0.5, -0.2, 0, 0, 0)])
def test_round_trip_with_distortion(dist):
    k1, k2, k3, p1, p2 = dist
    cam = CameraModel(0.05, 10e-6, 800, 600, 401.3, 297.8, k1, k2, k3, p1, p2)
    rng = np.random.default_rng(1)
    uv = np.column_stack([rng.uniform(0, 799, 200), rng.uniform(0, 599, 200)])
    v = cam.unproject(uv)
    assert np.allclose(np.linalg.norm(v, axis=1), 1.0)
    uv2, ok = cam.project(v)
    assert ok.all()
    assert np.abs(uv2 - uv).max() < 1e-8


def test_distortion_matches_formula():
    cam = CameraModel(0.1, 15e-6, 1024, 1024, 511.5, 511.5, k1=0.1, p1=0.01)
    xn, yn = 0.03, -0.02
    r2 = xn * xn + yn * yn
    xd = xn * (1 + 0.1 * r2) + 2 * 0.01 * xn * yn
    yd = yn * (1 + 0.1 * r2) + 0.01 * (r2 + 2 * yn * yn)
    u, v, ok = project_point(cam.as_array(), np.array([xn, yn, 1.0]))
    f = cam.focal_length_px
    assert (u, v) == pytest.approx((511.5 + f * xd, 511.5 + f * yd), abs=1e-9)
    assert ok  # 200 px right of centre, still on the sensor
    back = unproject_point(cam.as_array(), u, v)
    assert back[:2] / back[2] == pytest.approx([xn, yn], abs=1e-12)


def test_bad_inputs_raise():
    with pytest.raises(ConfigError):
        CameraModel(-0.1, 15e-6, 10, 10, 4.5, 4.5)
    with pytest.raises(ConfigError):
        camera_preset("nope")
    with pytest.raises(ConfigError):
        camera_preset("xing2012").project(np.zeros((3, 2)))
