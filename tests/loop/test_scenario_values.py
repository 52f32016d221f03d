"""Scenario values out of range are refused at load (exit 2) naming the key; the built-in
scenarios and Monte Carlo cases still load."""

import pytest
from gyrostar import config
from gyrostar.cli.main import main
from gyrostar.errors import ConfigError
from gyrostar.hil import config as hc

FAULT = 'faults = [ {{ kind = "link-corruption", at_s = {at}, seconds = {s}, rate = {rate} }} ]\n'


def _scenario(extra: str) -> str:
    return 'name = "x"\nduration_s = 10.0\n' + extra


@pytest.mark.parametrize("extra,expected", [
    (FAULT.format(at=-2.0, s=3.0, rate=0.01), "[faults[0]] at_s = -2.0 must be ≥ 0"),
    (FAULT.format(at=3.0, s=0.0, rate=0.01), "[faults[0]] seconds = 0.0 must be > 0"),
    (FAULT.format(at=3.0, s=3.0, rate=5.0), "[faults[0]] rate = 5.0 must be in [0, 1]"),
    (FAULT.format(at=3.0, s=3.0, rate=-0.1), "[faults[0]] rate = -0.1 must be in [0, 1]"),
    ('faults = [ { kind = "head-clock-step", at_s = 3.0 } ]\n', "[faults[0]] step_s = 0.0 must be a finite jump"),
    ('faults = [ { kind = "head-clock-step", at_s = 3.0, step_s = 0.0005 } ]\n', "of at least 0.001 s either way"),
    ('faults = [ { kind = "head-clock-step", at_s = 3.0, step_s = inf } ]\n',
     "key 'faults[0].step_s' must be a finite number"),
    ("min_track_fraction = 1.5\n", "min_track_fraction = 1.5 must be in [0, 1]"),
    ("min_track_fraction = -0.5\n", "min_track_fraction = -0.5 must be in [0, 1]"),
    ("max_error_arcsec_1sigma = -1.0\n", "max_error_arcsec_1sigma = -1.0 must be ≥ 0"),
    ("coast_timeout_s = 61.0\n", "coast_timeout_s = 61.0 must be in [0, 60] s"),
    ("coast_timeout_s = -1.0\n", "coast_timeout_s = -1.0 must be in [0, 60] s"),
    ("acquire_every_s = 61.0\n", "acquire_every_s = 61.0 must be in [0, 60] s"),
    ("acquire_every_s = -0.1\n", "acquire_every_s = -0.1 must be in [0, 60] s"),
    ("max_stars = 17\n", "max_stars = 17 must be in [0, 16]"),
    ("max_stars = -1\n", "max_stars = -1 must be in [0, 16]"),
])
def test_out_of_range_scenario_value_names_the_key(extra, expected):
    with pytest.raises(ConfigError) as err:
        config.loads(_scenario(extra), hc.Scenario, source="s.toml")
    assert str(err.value).startswith("s.toml: ") and expected in str(err.value), str(err.value)


def test_in_range_values_and_builtins_load():
    scen = config.loads(_scenario(FAULT.format(at=0.0, s=0.5, rate=1.0) + "min_track_fraction = 1.0\n"),
                        hc.Scenario)
    assert scen.faults[0].rate == 1.0 and scen.min_track_fraction == 1.0
    for name in hc.scenario_names():
        assert hc.load_scenario(name).name == name
    assert hc.load_scenario("mc:5@30").duration_s == 30.0


@pytest.mark.parametrize("spec", ["mc:5@nan", "mc:5@inf", "mc:5@-inf"])
def test_monte_carlo_spec_with_a_non_finite_duration_names_the_spec(spec, capsys):
    assert main(["run", "--scenario", spec, "--fast", "--no-plots"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and f"--scenario {spec}" in err and "DURATION" in err
    assert "--duration" not in err


def test_cli_run_refuses_a_fault_before_the_start(tmp_path, capsys):
    path = tmp_path / "scen.toml"
    path.write_text(_scenario(FAULT.format(at=-2.0, s=3.0, rate=0.01)))
    assert main(["run", "--scenario", str(path), "--fast", "--out", str(tmp_path / "run")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and str(path) in err and "at_s" in err
