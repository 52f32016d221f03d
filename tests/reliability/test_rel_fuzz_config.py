"""Hypothesis campaign over the TOML config loader: arbitrary text and arbitrary values for
real schemas (flatsat, scenario, calibration) give a validated object or ConfigError —
never another exception."""

import dataclasses

import pytest
from gyrostar import config
from gyrostar.calibration.calfile import Calibration
from gyrostar.errors import ConfigError
from gyrostar.hil import config as hc
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from rel_fuzz_support import fuzz_examples

pytestmark = pytest.mark.fuzz
N = fuzz_examples()
CFG = settings(max_examples=N, deadline=None, database=None, suppress_health_check=list(HealthCheck))
SCHEMAS = [hc.FlatsatConfig, hc.Scenario, Calibration]
DEFAULTS = {hc.FlatsatConfig: config.to_dict(hc.load_flatsat(None)),
            hc.Scenario: config.to_dict(hc.load_scenario("corruption"))}

keys = st.sampled_from(["name", "kind", "head", "gyro", "sim", "loop", "faults", "segments", "rate_dps",
                        "seconds", "at_s", "duration_s", "odr_hz", "eclipse", "x", "", "é"]) | st.text(max_size=6)
scalars = (st.none() | st.booleans() | st.integers(-2**63, 2**63 - 1) | st.floats(allow_nan=True)
           | st.text(max_size=12))
values = st.recursive(scalars, lambda c: st.lists(c, max_size=4) | st.dictionaries(keys, c, max_size=4),
                      max_leaves=12)


def _check(fn):
    try:
        out = fn()
    except ConfigError:
        return None
    return out


@CFG
@given(st.text(max_size=300), st.sampled_from(SCHEMAS))
def test_loads_arbitrary_text(cases, text, schema):
    cases["config.loads(arbitrary text)"] += 1
    out = _check(lambda: config.loads(text, schema))
    assert out is None or isinstance(out, schema)


toml_lines = st.lists(st.one_of(
    st.builds(lambda k, v: f"{k} = {v}", keys, st.sampled_from(
        ["1", "-3", "2.5", "nan", "inf", "true", '"x"', "[1, 2, 3]", "[0.1, 0.2]", "{ a = 1 }", "[[1], [2]]",
         '"emulator"', '"bmi088"', "1e400", "0x10", "[]", "{}", "[{ seconds = 1.0 }]", '""'])),
    st.sampled_from(["[head]", "[gyro]", "[sim]", "[loop]", "[outputs]", "[realtime]", "[[faults]]",
                     "[[segments]]", "[gyro_static]", "[x.y]", "[head.kind]"])), max_size=14)


@CFG
@given(toml_lines, st.sampled_from(SCHEMAS))
def test_loads_toml_like_text(cases, lines, schema):
    cases["config.loads(TOML-like lines)"] += 1
    out = _check(lambda: config.loads("\n".join(lines), schema))
    assert out is None or isinstance(out, schema)


@CFG
@given(st.dictionaries(keys, values, max_size=6), st.sampled_from(SCHEMAS))
def test_from_dict_arbitrary(cases, raw, schema):
    cases["config.from_dict(arbitrary)"] += 1
    out = _check(lambda: config.from_dict(raw, schema))
    assert out is None or isinstance(out, schema)


def _paths(d, prefix=()):
    for k, v in d.items():
        yield prefix + (k,)
        if isinstance(v, dict):
            yield from _paths(v, prefix + (k,))


@CFG
@given(st.sampled_from(list(DEFAULTS)), st.data())
def test_valid_config_with_one_value_replaced(cases, schema, data):
    """A real config with one key set to an arbitrary value: validated or ConfigError, and
    a validated object round-trips through to_dict/from_dict."""
    cases["config.from_dict(one value replaced)"] += 1
    import copy

    raw = copy.deepcopy(DEFAULTS[schema])
    path = data.draw(st.sampled_from(list(_paths(raw))))
    node = raw
    for k in path[:-1]:
        node = node[k]
    node[path[-1]] = data.draw(values)
    out = _check(lambda: config.from_dict(raw, schema))
    if out is not None:
        again = config.from_dict(config.to_dict(out), schema)
        assert dataclasses.asdict(again) == dataclasses.asdict(out) or _has_nan(out)


def _has_nan(obj) -> bool:
    return "nan" in repr(dataclasses.asdict(obj))
