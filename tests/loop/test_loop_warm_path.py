"""Every numba function of the flight code that the loop or its head worker calls from Python
is compiled or loaded before the first step (the loop's ``warmup()``, the identifier's
warm-up): loading one from the cache while the loop runs holds the interpreter lock ~10 ms,
compiling it on an empty cache ~1 s — a real-time run then loses gyro samples (a 30 s run
lost 95 at 1 s, when the gyro timebase's first fit and the acquisition's ``unproject_many``
were loaded)."""

import sys

import pytest
from numba.core.registry import CPUDispatcher


def _flight_dispatchers():
    """{qualified name: dispatcher} of the njit functions of the flight modules loaded now."""
    out = {}
    for name, mod in list(sys.modules.items()):
        if not name.startswith("gyrostar.") or name.startswith(("gyrostar.mocks", "gyrostar.hil")):
            continue
        for obj in list(vars(mod).values()):
            if isinstance(obj, CPUDispatcher):
                out[f"{obj.py_func.__module__}.{obj.py_func.__qualname__}"] = obj
    return out


@pytest.mark.parametrize("fast", [True, False], ids=["fast", "realtime"])
def test_no_flight_kernel_is_first_loaded_while_the_loop_runs(tmp_path, monkeypatch, fast):
    from gyrostar.hil import config as hc
    from gyrostar.hil.runner import run_flatsat
    from gyrostar.loop.coupled import CoupledLoop

    loaded: set = set()
    seen = {"modules": -1, "dispatchers": {}, "base": None}
    step = CoupledLoop.step

    def dispatchers():
        if len(sys.modules) != seen["modules"]:       # a module imported since: look again
            seen["modules"] = len(sys.modules)
            seen["dispatchers"] = _flight_dispatchers()
        return seen["dispatchers"]

    def watched(self):
        if seen["base"] is None:     # the first step: every warm-up is done
            seen["base"] = {k: len(d.signatures) for k, d in dispatchers().items()}
        try:
            return step(self)
        finally:   # loaded since the first step, in a step or on another thread (the head worker)
            for k, d in dispatchers().items():
                if len(d.signatures) > seen["base"].get(k, 0):
                    loaded.add(k)

    monkeypatch.setattr(CoupledLoop, "step", watched)
    # the demo scenario: acquisition, tracking, the first coast and the gyro timebase's fits
    run_flatsat(hc.load_flatsat(), hc.load_scenario("demo"), duration=8.0 if fast else 4.0, seed=1,
                folder=tmp_path / "run", plots=False, status=False, fast=fast)
    assert not loaded, f"loaded or compiled while the loop ran (add them to the loop's warmup): {loaded}"
