"""Every numba function of the flight code that the loop or its head worker calls from Python
is compiled or loaded before the first step (the loop's ``warmup()``, the identifier's
warm-up), with the signatures the loop calls it with: loading one from the cache while the
loop runs holds the interpreter lock ~10 ms, compiling it on an empty cache ~1 s — a
real-time run then loses gyro samples (a 30 s run lost 95 at 1 s, when the gyro timebase's
first fit and the acquisition's ``unproject_many`` were loaded) or frames (a new user's first
``make run`` lost 1 s of frames and failed the demo's acceptance: ``ClockSync`` called
``drift_fit`` with strided column views, the warm-up had compiled it for contiguous arrays).

Each case runs in a fresh interpreter: in this test session other tests have compiled most
signatures already (the strided ``drift_fit`` among them), which hid a lazy one.
"""

import json
import subprocess
import sys

import pytest

PROBE = r"""
import json, sys, tempfile, pathlib, dataclasses
from numba.core.registry import CPUDispatcher
from gyrostar.hil import config as hc
from gyrostar.hil.runner import run_flatsat
from gyrostar.loop.coupled import CoupledLoop

mode, fast, seconds = sys.argv[1], sys.argv[2] == "fast", float(sys.argv[3])

def flight_dispatchers():
    # {qualified name: dispatcher} of the njit functions of the flight modules loaded now
    out = {}
    for name, mod in list(sys.modules.items()):
        if mod is None or not name.startswith("gyrostar.") or name.startswith(("gyrostar.mocks", "gyrostar.hil")):
            continue
        for obj in list(vars(mod).values()):
            if isinstance(obj, CPUDispatcher):
                out[obj.py_func.__module__ + "." + obj.py_func.__qualname__] = obj
    return out

seen = {"modules": -1, "dispatchers": {}, "base": None}
loaded = {}
step = CoupledLoop.step

def dispatchers():
    if len(sys.modules) != seen["modules"]:       # a module imported since: look again
        seen["modules"] = len(sys.modules)
        seen["dispatchers"] = flight_dispatchers()
    return seen["dispatchers"]

def watched(self):
    if seen["base"] is None:     # the first step: every warm-up is done
        seen["base"] = {k: [str(s) for s in d.signatures] for k, d in dispatchers().items()}
    try:
        return step(self)
    finally:   # met since the first step, in a step or on another thread (the head worker)
        for k, d in dispatchers().items():
            extra = [str(s) for s in d.signatures if str(s) not in seen["base"].get(k, [])]
            if extra:
                loaded[k] = extra

CoupledLoop.step = watched
cfg = hc.load_flatsat()
cfg = dataclasses.replace(cfg, head=dataclasses.replace(cfg.head, mode=mode))
with tempfile.TemporaryDirectory() as folder:
    res = run_flatsat(cfg, hc.load_scenario("demo"), duration=seconds, seed=1, folder=pathlib.Path(folder),
                      plots=False, status=False, fast=fast)
print(json.dumps({"dispatchers": len(seen["base"] or {}), "loaded": loaded, "frames": res["frames"],
                  "track_s": res["mode_seconds"]["TRACK"]}))
"""


@pytest.mark.parametrize("mode, clock, seconds", [("stream", "fast", 30.0), ("request", "fast", 12.0),
                                                  ("stream", "realtime", 4.0)])
def test_no_flight_kernel_is_first_loaded_while_the_loop_runs(mode, clock, seconds):
    """The demo scenario (acquisition, tracking, a 5 °/s slew from 3 s, 4 s without stars
    from 20 s, recovery; the time sync's and the gyro timebase's fits): after the run every
    flight dispatcher has only the signatures it had at the first step."""
    out = subprocess.run([sys.executable, "-c", PROBE, mode, clock, str(seconds)], capture_output=True, text=True,
                         timeout=900)
    assert out.returncode == 0, out.stderr[-3000:]
    got = json.loads(out.stdout.strip().splitlines()[-1])
    assert got["dispatchers"] > 50 and got["frames"] > 40 * seconds and got["track_s"] > 0.5 * seconds, got
    assert got["loaded"] == {}, f"loaded or compiled while the loop ran (warm them up): {got['loaded']}"
