"""pytest plugin for the HIL scenarios: ``pytest hil [--flatsat CONFIG] [--hil-out DIR]``.

Without ``--flatsat`` the built-in simulated flatsat runs (head emulator and BMI088 model);
``--flatsat hil/flatsat_fwhost.toml`` puts the firmware's host program on a pty in place
of the emulator; a config naming real devices runs the scenarios on the bench (scenarios
that need the simulator's truth or its fault injection are skipped there).
"""

from __future__ import annotations

import pytest


def pytest_addoption(parser):
    group = parser.getgroup("gyrostar HIL")
    group.addoption("--flatsat", default=None, metavar="CONFIG",
                    help="flatsat config TOML (default: the built-in simulated flatsat)")
    group.addoption("--hil-out", default=None, metavar="DIR",
                    help="keep each scenario's run folder (log, summary, plots) under DIR")


@pytest.fixture(scope="session")
def flatsat_config(request):
    from gyrostar.hil import config as hc

    return hc.load_flatsat(request.config.getoption("--flatsat"))


@pytest.fixture
def run_dir(request, tmp_path):
    from pathlib import Path

    out = request.config.getoption("--hil-out")
    if out:
        d = Path(out) / request.node.name.replace("[", "_").replace("]", "")
        d.mkdir(parents=True, exist_ok=True)
        return d
    return tmp_path
