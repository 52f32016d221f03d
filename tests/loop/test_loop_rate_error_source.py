"""Where the loop's rate-proportional gyro error comes from: a simulated part's own scale and
misalignment errors until a [gyro_scale] calibration takes them out, then the config's
residual; a calibrated simulated set (no such errors) has none."""

import math

from gyrostar.calibration.apply import RunCalibration
from gyrostar.calibration.calfile import Calibration, GyroScaleCal
from gyrostar.hil import config as hc
from gyrostar.hil.flatsat import gyro_scale_calibrated, loop_params

I3 = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]


def test_the_rate_error_is_the_parts_until_a_scale_calibration():
    cfg = hc.load_flatsat(None)
    miscal = hc.load_scenario("miscal")              # BMI088: 3300 ppm scale, 3.3 mrad misalignment (1σ)
    raw = loop_params(cfg, scen=miscal).gyro_rate_error
    assert math.isclose(raw, math.hypot(3300e-6, 3.3e-3), rel_tol=1e-12)
    cal = RunCalibration(Calibration(gyro_scale=GyroScaleCal(I3, I3, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))))
    assert gyro_scale_calibrated(cal)
    assert not gyro_scale_calibrated(RunCalibration(None)) and not gyro_scale_calibrated(None)
    assert not gyro_scale_calibrated(RunCalibration(Calibration()))
    after = loop_params(cfg, scen=miscal, scale_calibrated=True).gyro_rate_error
    assert after == cfg.loop.gyro_rate_error_ppm * 1e-6 and math.isclose(after, 200e-6, rel_tol=1e-12)
    assert loop_params(cfg, scen=hc.load_scenario("demo")).gyro_rate_error == 0.0   # xing2012: calibrated set
