"""The console script: sub-commands, --help, exit codes, JSON on stdout only."""

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from gyrostar.cli.main import COMMANDS, main

GYROSTAR = [str(Path(sys.executable).parent / "gyrostar")]


def test_help_lists_every_subcommand():
    out = subprocess.run(GYROSTAR + ["--help"], capture_output=True, text=True, check=True).stdout
    for name in ("run", "eval", "bench", "calibrate", "replay", "fw", "sim", "solve"):
        assert name in out
    assert "exit codes" in out


@pytest.mark.parametrize("name", sorted(COMMANDS))
def test_each_subcommand_has_help(name, capsys):
    with pytest.raises(SystemExit) as exc:
        main([name, "--help"])
    assert exc.value.code == 0
    assert "usage: gyrostar " + name in capsys.readouterr().out


def test_unknown_bench_suite_is_usage_error(capsys):
    assert main(["bench", "no-such-suite", "-q"]) == 2


def test_bench_list_json_is_single_object():
    env = dict(os.environ)
    res = subprocess.run(GYROSTAR + ["bench", "--list", "--json"], capture_output=True, text=True, env=env)
    assert res.returncode == 0, res.stderr
    obj = json.loads(res.stdout)
    assert isinstance(obj["suites"], list)
