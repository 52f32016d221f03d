"""The ``calibrate … --simulate`` front ends refuse bad numbers and missing files before any
work: exit 2 (usage/config, README) and one line naming the flag, no traceback.

Every case fails at parse time or in the checks that precede the simulation, so the table is fast."""

import pytest
from gyrostar.cli.main import main

USAGE = 2

# (calibrate target and its arguments, the flag the one line must name)
CASES = [
    # alignment
    (["alignment", "--camera-hz", "nan"], "--camera-hz"),
    (["alignment", "--camera-hz", "0"], "--camera-hz"),
    (["alignment", "--camera-hz", "100000"], "--camera-hz"),
    (["alignment", "--amplitudes", "foo"], "--amplitudes"),
    (["alignment", "--amplitudes", "20,16"], "--amplitudes"),
    (["alignment", "--amplitudes", "20,inf,12"], "--amplitudes"),
    (["alignment", "--lag", "0"], "--lag"),
    (["alignment", "--max-offset-ms", "-5"], "--max-offset-ms"),
    (["alignment", "--max-offset-ms", "nan"], "--max-offset-ms"),
    (["alignment", "--clock-offset-ms", "nan"], "--clock-offset-ms"),
    (["alignment", "--duration", "0"], "--duration"),
    (["alignment", "--duration", "1e9"], "--duration"),
    (["alignment", "--duration", "5", "--lag", "10"], "--lag"),
    (["alignment", "--gyro-cal", "nofile.toml"], "--gyro-cal"),
    (["alignment", "--set", "odr_hz=nan"], "--set"),
    (["alignment", "--set", "no_such_key=1"], "--set"),
    # gyro-scale
    (["gyro-scale", "--run-seconds", "0"], "--run-seconds"),
    (["gyro-scale", "--run-seconds", "1e9"], "--run-seconds"),
    (["gyro-scale", "--method", "slew", "--duration", "0"], "--duration"),
    (["gyro-scale", "--method", "slew", "--alignment", "nofile.toml"], "--alignment"),
    (["gyro-scale", "--trim", "-1"], "--trim"),
    (["gyro-scale", "--trim", "5", "--run-seconds", "10"], "--trim"),
    (["gyro-scale", "--rates", "10,x"], "--rates"),
    (["gyro-scale", "--rates", "nan"], "--rates"),
    (["gyro-scale", "--set", "internal_hz=6400", "--run-seconds", "600", "--rates", "1,2,3,4,5,6,7,8,9,10"],
     "--run-seconds"),
    # gyro-static
    (["gyro-static", "--hours", "1e9"], "--hours"),
    (["gyro-static", "--hours", "nan"], "--hours"),
    (["gyro-static", "--set", "internal_hz=1e9"], "--set"),
    (["gyro-static", "--set", "internal_hz=6400", "--set", "odr_hz=400", "--hours", "12"], "--hours"),
    # dark
    (["dark", "--temperature", "nan"], "--temperature"),
    (["dark", "--k-sigma", "-1"], "--k-sigma"),
    (["dark", "--hot-factor", "nan"], "--hot-factor"),
    (["dark", "--frames", "100000"], "--frames"),
    (["dark", "--exposures", "1e6"], "--exposures"),
    # camera
    (["camera", "--outliers", "2"], "--outliers"),
    (["camera", "--outliers", "0.99"], "--outliers"),
    (["camera", "--outliers", "nan"], "--outliers"),
    (["camera", "--centroid-noise", "-1"], "--centroid-noise"),
    (["camera", "--centroid-noise", "inf"], "--centroid-noise"),
    (["camera", "--fields", "100000000"], "--fields"),
    (["camera", "--mag-limit", "nan"], "--mag-limit"),
    (["camera", "--fix", "bogus"], "--fix"),
    (["gyro-static", "--gyro-params", "foo"], "--gyro-params"),
    (["alignment", "--gyro-params", "foo"], "--gyro-params"),
    (["gyro-scale", "--gyro-params", "foo"], "--gyro-params"),
]


@pytest.mark.parametrize(("args", "flag"), CASES, ids=[" ".join(a) for a, _ in CASES])
def test_bad_simulate_argument_is_refused_naming_the_flag(args, flag, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("GYROSTAR_RUNS", str(tmp_path / "runs"))
    argv = ["calibrate", *args, "--simulate", "--no-plots", "--report", str(tmp_path / "report")]
    try:
        code = main(argv)
    except SystemExit as exc:          # argparse: one usage line and exit 2
        code = exc.code
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.strip()]
    assert code == USAGE, err
    assert len(lines) == 1, err
    assert flag in lines[0]
    assert "Traceback" not in err and "internal error" not in err
    assert not (tmp_path / "report").exists() or not any((tmp_path / "report").iterdir())


LIVE_CASES = [
    (["--duration", "1e9"], "--duration"),
    (["--duration", "nan"], "--duration"),
    (["--range-dps", "300"], "--range-dps"),
    (["--address", "0x99"], "--address"),
    (["--address", "foo"], "--address"),
    (["--i2c-bus", "-1"], "--i2c-bus"),
]


@pytest.mark.parametrize(("args", "flag"), LIVE_CASES, ids=[" ".join(a) for a, _ in LIVE_CASES])
def test_bad_live_argument_is_refused_naming_the_flag(args, flag, tmp_path, capsys):
    """``calibrate gyro-static --live``: the record length is bounded (memory), the range is one
    the BMI088 has, the address a 7-bit one — refused before any device is opened."""
    try:
        code = main(["calibrate", "gyro-static", "--live", *args, "--report", str(tmp_path / "report")])
    except SystemExit as exc:
        code = exc.code
    err = capsys.readouterr().err
    assert code == USAGE and flag in err and "Traceback" not in err and len(err.strip().splitlines()) == 1
