"""The flight CLI reaches ground commands only through entry points: every registered
command and target imports and has the target interface (the import contract of make lint
checks that no flight module imports them)."""

import importlib
from importlib.metadata import entry_points

from gyrostar.cli import calibrate, evaluate, sim


def test_registered_ground_commands_and_targets_load():
    cmds = {ep.name: ep.value for ep in entry_points(group="gyrostar.commands")}
    assert set(cmds) >= {"run", "replay"}
    for module in cmds.values():
        assert callable(importlib.import_module(module).run)
    targets = {ep.name: ep.value for ep in entry_points(group="gyrostar.targets")}
    assert {"calibrate.camera", "calibrate.alignment", "calibrate.gyro-scale", "calibrate.gyro-static",
            "calibrate.dark", "eval.centroid", "eval.starcount", "sim.frame"} <= set(targets)
    for module in targets.values():
        m = importlib.import_module(module)
        assert isinstance(m.HELP, str) and callable(m.configure) and callable(m.run)
    assert set(calibrate.TARGETS) == {"camera", "alignment", "gyro-scale", "gyro-static", "dark"}
    assert {"centroid", "starcount", "starid"} <= set(evaluate.TARGETS) and "frame" in sim.TARGETS

