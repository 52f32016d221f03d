"""Config validation: unknown or ill-typed keys name the key, the file and the type."""

from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import pytest
from gyrostar import config
from gyrostar.errors import ConfigError


@dataclass
class Gyro:
    bus: int = 1
    address: int = 0x68
    kind: Literal["bmi088", "l3gd20h"] = "bmi088"


@dataclass
class Flatsat:
    name: str
    rate_hz: float = 400.0
    gyro: Gyro = field(default_factory=Gyro)
    urls: list[str] = field(default_factory=list)
    offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    log: Path | None = None


def test_valid_file_round_trips(tmp_path):
    p = tmp_path / "f.toml"
    p.write_text('name = "bench"\nrate_hz = 400\nurls = ["loop://"]\noffset = [1, 2.5, 3]\n'
                 'log = "/tmp/x.log"\n[gyro]\nbus = 2\nkind = "l3gd20h"\n')
    cfg = config.load(p, Flatsat)
    assert cfg.rate_hz == 400.0 and isinstance(cfg.rate_hz, float)
    assert cfg.gyro == Gyro(bus=2, address=0x68, kind="l3gd20h")
    assert cfg.offset == (1.0, 2.5, 3.0)
    assert cfg.log == Path("/tmp/x.log")
    assert config.to_dict(cfg)["gyro"]["kind"] == "l3gd20h"


def test_unknown_key_names_key_and_file(tmp_path):
    p = tmp_path / "bad.toml"
    p.write_text('name = "x"\n[gyro]\nbuss = 1\n')
    with pytest.raises(ConfigError) as err:
        config.load(p, Flatsat)
    msg = str(err.value)
    assert "gyro.buss" in msg and str(p) in msg and "bus" in msg


@pytest.mark.parametrize("text,key,expected", [
    ('name = 3', "name", "a string"),
    ('name = "x"\nrate_hz = "fast"', "rate_hz", "a number"),
    ('name = "x"\n[gyro]\nbus = 1.5', "gyro.bus", "an integer"),
    ('name = "x"\n[gyro]\nbus = true', "gyro.bus", "an integer"),
    ('name = "x"\nurls = [1]', "urls[0]", "a string"),
    ('name = "x"\noffset = [1, 2]', "offset", "3 items"),
    ('name = "x"\n[gyro]\nkind = "mpu6050"', "gyro.kind", "one of"),
    ('name = "x"\nrate_hz = nan', "rate_hz", "finite"),
    ('name = "x"\nrate_hz = -inf', "rate_hz", "finite"),
    ('name = "x"\noffset = [0.0, inf, 0.0]', "offset[1]", "finite"),
])
def test_ill_typed_key_names_expected_type(text, key, expected):
    with pytest.raises(ConfigError) as err:
        config.loads(text, Flatsat, source="cfg.toml")
    msg = str(err.value)
    assert f"'{key}'" in msg and expected in msg and "cfg.toml" in msg


def test_missing_required_and_bad_toml(tmp_path):
    with pytest.raises(ConfigError, match="missing required key 'name'"):
        config.loads("rate_hz = 1", Flatsat)
    with pytest.raises(ConfigError, match="not valid TOML"):
        config.loads("name = ", Flatsat)
    with pytest.raises(ConfigError, match="does not exist"):
        config.load(tmp_path / "nope.toml", Flatsat)


def test_validate_hook_reports_range_errors():
    @dataclass
    class Exposure:
        ms: float = 10.0

        def validate(self):
            if not 0 < self.ms <= 1000:
                raise ValueError(f"ms must be in (0, 1000], got {self.ms}")

    with pytest.raises(ConfigError, match="ms must be in"):
        config.loads("ms = -1", Exposure, source="e.toml")


def test_non_utf8_file_is_a_config_error_naming_the_file(tmp_path):
    p = tmp_path / "bin.toml"
    p.write_bytes(b"\xff\xfe[a]\n")
    with pytest.raises(ConfigError, match=f"config file {p} is not UTF-8 text TOML"):
        config.load(p, Flatsat)
    with pytest.raises(ConfigError, match="is a folder, not a regular file"):
        config.load(tmp_path, Flatsat)           # a directory
    p.write_text('name = "é"\n', encoding="utf-8")   # non-ASCII UTF-8 still loads
    assert config.load(p, Flatsat).name == "é"


@dataclass
class Tilt:
    deg: float

    def validate(self):
        if not self.deg >= 0:
            raise ValueError(f"tilt.deg must be ≥ 0, got {self.deg}")


@dataclass
class Mount:
    tilt: Tilt | None = None
    pair: tuple[float, float] | None = None
    either: int | str = 0


@pytest.mark.parametrize("text,expected", [
    ("[tilt]", "missing required key 'tilt.deg' (a number)"),
    ("[tilt]\ndeg = 1\nspin = 2", "unknown key 'tilt.spin'"),
    ('[tilt]\ndeg = "big"', "key 'tilt.deg' expects a number, got string"),
    ("[tilt]\ndeg = nan", "key 'tilt.deg' must be a finite number"),
    ("[tilt]\ndeg = -5.0", "tilt.deg must be ≥ 0, got -5.0"),
    ("pair = [1, 2, 3]", "key 'pair' must have 2 items, got 3"),
])
def test_optional_nested_table_reports_the_inner_error(text, expected):
    with pytest.raises(ConfigError) as err:
        config.loads(text, Mount, source="m.toml")
    msg = str(err.value)
    assert msg.startswith("m.toml: ") and expected in msg and "(optional)" not in msg
    assert config.loads("[tilt]\ndeg = 2", Mount).tilt == Tilt(2.0)
    assert config.loads("", Mount).tilt is None


def test_union_of_two_types_still_reports_the_union():
    assert config.loads('either = "x"', Mount).either == "x"
    with pytest.raises(ConfigError, match="key 'either' expects an integer or a string, got float"):
        config.loads("either = 1.5", Mount)
