"""A partial flatsat config is the built-in simulated flatsat with its keys changed: the
schema's defaults are the built-in file's values, so a two-line override file does not
silently swap the gyro model or drop the loop's real-time priority."""

import dataclasses

from gyrostar.hil import config as hc


def _flat(obj, prefix=""):
    out = {}
    for f in dataclasses.fields(obj):
        v = getattr(obj, f.name)
        if dataclasses.is_dataclass(v):
            out.update(_flat(v, prefix + f.name + "."))
        else:
            out[prefix + f.name] = v
    return out


def test_an_override_file_changes_only_its_keys(tmp_path):
    built_in = _flat(hc.load_flatsat(None))
    p = tmp_path / "mine.toml"
    p.write_text('name = "my bench"\n[loop]\nframe_hz = 50.0\n')
    mine = _flat(hc.load_flatsat(p))
    assert mine.keys() == built_in.keys()
    differ = {k for k in built_in if mine[k] != built_in[k]}
    assert differ == {"name", "loop.frame_hz"}
    assert mine["sim.gyro_errors"] == "xing2012" and mine["realtime.sched_fifo_priority"] == 50
