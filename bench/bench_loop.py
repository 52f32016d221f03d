"""Real-time coupled loop on the simulated flatsat (emulated devices, 400 Hz gyro / ~100 Hz
frames): sample-to-output latency p99, loop CPU, overruns; numba start-up cold and cached.

The run uses the built-in flatsat (head emulator in a child process, BMI088 register
model) on the host monotonic clock for 300 s (``--quick``: 20 s), with a host wake-up
probe beside it (:mod:`gyrostar.loop.wakeup_probe`) that tells overruns the host caused
from the loop's own. Baseline of the
latency figure, measured in the same run: the same per-sample path (MEKF predict + star
projection) executed as plain Python (the numba functions' ``py_func``). The gyro path's
figure comes with this host's floor for it at the run's step schedule (``host_floor_us``:
one compiled call per wake-up and one output record per sample, the thread asleep between
wake-ups as many gyro periods as the run's mean samples per step; with the default FIFO
watermark of 4 the loop steps every 4 samples or at once when a frame is measured), and
beside it the least any such path can cost here (``host_bare_call_us``: one compiled call
per wake-up that writes the wake-up's records itself, no Python around it).
"""

from __future__ import annotations

import os
import tempfile
import time
from pathlib import Path

import numpy as np


def _per_sample_us(predict, project, n=400) -> float:
    from gyrostar.core.mekf import mekf_init

    q, b, P = mekf_init(np.array([0.0, 0.0, 0.0, 1.0]), np.zeros(3), 1e-4, 1e-3)
    cam = np.array([6666.6, 511.5, 511.5, 0, 0, 0, 0, 0, 1024, 1024])
    refs = np.random.default_rng(0).normal(size=(12, 3)) * 0.03 + np.array([0, 0, 1.0])
    refs /= np.linalg.norm(refs, axis=1)[:, None]
    w = np.array([1e-3, -2e-3, 5e-4])
    predict(q, b, P, w, 0.0025, 2.4e-4, 1e-6)
    project(cam, q, refs)
    t0 = time.perf_counter()
    for _ in range(n):
        predict(q, b, P, w, 0.0025, 2.4e-4, 1e-6)
        project(cam, q, refs)
    return (time.perf_counter() - t0) / n * 1e6


def _gyro_path_us(n_steps=4000) -> tuple[float, float, float]:
    """Host µs per gyro sample of the 400 Hz path after the FIFO read, one sample per FIFO
    batch (watermark 1), 12 tracked stars, one recorder-style sink: the loop's stages
    (batch kernel + output stage) vs the per-sample Python path they replaced (MEKF predict,
    star projection and record fields set from Python for each sample), same process; and the
    stages paced at 400 Hz with the thread asleep in between (µs CPU per sample)."""
    from gyrostar.clock import MONOTONIC
    from gyrostar.core.mekf import mekf_predict
    from gyrostar.gyro import GyroSamples
    from gyrostar.loop import record as R
    from gyrostar.loop.attitude_filter import AttitudeFilter
    from gyrostar.loop.kernels import project_refs
    from gyrostar.loop.outputs import OutputStage

    cam = np.array([6666.6, 511.5, 511.5, 0, 0, 0, 0, 0, 1024, 1024])
    refs = np.random.default_rng(0).normal(size=(12, 3)) * 0.03 + np.array([0, 0, 1.0])
    refs /= np.linalg.norm(refs, axis=1)[:, None]
    ids = np.arange(12, dtype=np.int32)
    sink_bytes = []

    class Sink:
        def put(self, recs, t_ns):
            sink_bytes.append(len(recs.tobytes()))
            if len(sink_bytes) > 64:
                sink_bytes.clear()

    smp = GyroSamples(256)
    smp.n = 1
    smp.rate[0] = [1e-3, -2e-3, 5e-4]
    f = AttitudeFilter(1.7e-4, 1e-6, 0.02, 0.0025)
    o = OutputStage([Sink()], MONOTONIC)
    slots = np.arange(12)
    uv = np.zeros((R.MAX_STARS, 2))

    def stage_step(k):
        smp.t[0] = 1.0 + k * 0.0025
        t_read = MONOTONIC.now()
        out = o.batch(smp.n)
        f.predict(smp, 0, R.FLAG_ATTITUDE_VALID, R.MODE_TRACK, refs, ids, cam, slots, uv, out)
        o.emit(out, t_read, f.t_last)

    buf = R.empty(256)
    blank = R.empty(1)[0]
    q, b, P = f.q.copy(), f.b.copy(), f.P.copy()
    sink = Sink()

    def per_sample_step(k):
        t_read = MONOTONIC.now()
        out = buf[:1]
        out[:] = blank
        for i in range(smp.n):
            w = smp.rate[i]
            mekf_predict(q, b, P, w, 0.0025, 1.7e-4, 1e-6)
            o_ = out[i]
            o_["t"] = 1.0 + k * 0.0025
            o_["seq"] = k
            o_["mode"] = R.MODE_TRACK
            o_["flags"] = R.FLAG_ATTITUDE_VALID
            o_["q"] = q
            o_["omega"] = w - b
            o_["bias"] = b
            o_["cov"] = P
            uvs, _ = project_refs(cam, q, refs)
            o_["star_id"][:12] = ids
            o_["centroid_px"][:12] = uvs
            o_["n_stars"] = 12
        out["latency_us"] = (MONOTONIC.now() - t_read) * 1e6
        sink.put(out, 0)

    res = []
    for fn, n in ((stage_step, n_steps), (per_sample_step, n_steps // 4)):
        fn(0)
        t0 = time.perf_counter()
        for k in range(n):
            fn(k)
        res.append((time.perf_counter() - t0) / n * 1e6)
    # the same stages once every gyro period, the thread asleep in between (as in a run, but
    # with nothing else to run): what waking up to a cold cache costs this host
    cpu = 0.0
    n_paced = n_steps // 2
    for k in range(n_paced):
        time.sleep(0.0025)
        c0 = time.thread_time()
        stage_step(k)
        cpu += time.thread_time() - c0
    return res[0], res[1], cpu / n_paced * 1e6


def _paced_cpu_us(fn, args: tuple, n: int, samples_per_wake: float, period_s: float) -> float:
    """CPU µs per sample of ``fn(*args, lo, m)`` called once per wake-up for the ``m``
    samples ``lo …`` of that wake-up, the thread asleep ``m`` periods of ``period_s`` before
    each (every ``samples_per_wake`` gyro periods on average, the run's own mean)."""
    cpu = 0.0
    carry = 0.0
    samples = 0
    for _ in range(n):
        carry += samples_per_wake
        m = max(1, int(carry))
        carry -= m
        time.sleep(period_s * m)
        c0 = time.thread_time()
        fn(*args, samples, m)
        cpu += time.thread_time() - c0
        samples += m
    return cpu / samples * 1e6


def _host_wake_floor_us(n: int = 1000, samples_per_wake: float = 1.0, period_s: float = 0.0025) -> float:
    """CPU µs per sample this host charges for the least a gyro path can do once its thread
    has slept: per wake-up (every ``samples_per_wake`` gyro periods of ``period_s``, the
    run's own mean) one compiled call (a quaternion normalised) and, per sample, one output
    record written into the next row of a preallocated buffer — a floor for
    ``host_us_per_gyro_sample`` on this host at the run's step schedule for a path that
    hands each record on from Python (:func:`_host_bare_floor_us`: for one that does not)."""
    from gyrostar.attitude import quat_normalize
    from gyrostar.loop import record as R

    q = np.array([0.1, 0.2, 0.3, 0.9])
    rec = R.empty(1)
    rows = R.empty(256)
    quat_normalize(q)

    def wake(lo, m):
        rec["q"][0] = quat_normalize(q)
        for i in range(lo, lo + m):
            rows[i % 256] = rec[0]

    return _paced_cpu_us(wake, (), n, samples_per_wake, period_s)


def _host_bare_floor_us(n: int = 1000, samples_per_wake: float = 1.0, period_s: float = 0.0025) -> float:
    """CPU µs per sample this host charges for one compiled call per wake-up and nothing
    else: the call (two array arguments) normalises a quaternion and writes it into the
    wake-up's output records in compiled code; no Python runs around it but the loop that
    sleeps. The least any 400 Hz path with one numba call per FIFO batch can cost on this
    host at that schedule (the thread asleep ``samples_per_wake`` gyro periods between
    calls, as in the run)."""
    from gyrostar.loop import record as R
    from numba import njit

    @njit  # no cache: this module is loaded from a path by the bench runner
    def write_records(q, out, lo, m):
        s = np.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
        for i in range(m):
            r = out[(lo + i) % out.shape[0]]
            for j in range(4):
                r["q"][j] = q[j] / s
        return m

    q = np.array([0.1, 0.2, 0.3, 0.9])
    rows = R.empty(256)
    write_records(q, rows, 0, 1)
    return _paced_cpu_us(write_records, (q, rows), n, samples_per_wake, period_s)


def run(quick: bool) -> dict:
    from gyrostar.core.mekf import mekf_predict
    from gyrostar.hil import config as hc
    from gyrostar.hil.runner import run_flatsat
    from gyrostar.loop.kernels import project_refs
    from gyrostar.loop.wakeup_probe import WakeupProbe
    from gyrostar.loop.warmup import measure_startup

    duration = 20.0 if quick else 300.0
    cfg = hc.load_flatsat()
    scen = hc.load_scenario("demo")
    # the host's own real-time wake-up latency beside the loop, one priority above it
    probe = WakeupProbe(priority=cfg.realtime.sched_fifo_priority + 1 if cfg.realtime.sched_fifo_priority else 0)
    with tempfile.TemporaryDirectory() as tmp:
        res = run_flatsat(cfg, scen, duration=duration, seed=1, folder=Path(tmp), realtime=True, plots=False,
                          status=False, record=True, probe=probe)
    hw = res["host_wakeups"]
    load = os.getloadavg()
    numba_us = _per_sample_us(mekf_predict, project_refs)
    py_us = _per_sample_us(mekf_predict.py_func, project_refs.py_func, n=100)
    p99_us = res["latency_p99_ms"] * 1e3
    startup = {} if quick else measure_startup()
    stage_us, per_sample_us, paced_us = _gyro_path_us()
    sps = res.get("samples_per_step") or 1.0
    floor_us = _host_wake_floor_us(samples_per_wake=sps, period_s=1.0 / cfg.gyro.odr_hz)
    floor_1_us = _host_wake_floor_us()
    bare_us = _host_bare_floor_us(samples_per_wake=sps, period_s=1.0 / cfg.gyro.odr_hz)
    in_run_us = res["host_us_per_gyro_sample"]            # CPU of the loop thread in the path
    in_run_wall_us = res["host_us_per_gyro_sample_wall"]  # wall: with the turns other threads took in it
    dev = res.get("device_emulation_cpu_percent")
    thread = res.get("loop_thread_cpu_percent")
    dev_note = (f" (of which {dev:.1f} % inside the emulated gyro)" if dev is not None else "") + (
        f"; {thread:.1f} % with the scheduler's idle ticks" if thread is not None else "")
    proc = res.get("process_cpu_percent")
    proc_note = f", the process (loop, head worker, link reader, log writer) {proc:.1f} %" if proc is not None else ""
    sched = (f"{res['loop_steps']} loop steps, {sps:.2f} gyro samples per step (FIFO watermark "
             f"{cfg.gyro.fifo_watermark}: a step every {cfg.gyro.fifo_watermark} samples or at a frame), sample age "
             f"at its step p50/p99 {res.get('sample_age_at_step_ms_p50', float('nan')):.1f}/"
             f"{res.get('sample_age_at_step_ms_p99', float('nan')):.1f} ms, exposure → output p50 "
             f"{res.get('exposure_to_output_ms_p50', float('nan')):.1f} ms")
    note = (f"{duration:.0f} s real time: p99 sample→output {p99_us:.0f} µs, {sched}, "
            f"loop CPU {res['cpu_percent']:.1f} %{dev_note}{proc_note}, "
            f"overruns {res['overruns']}, frames {res['frames']}, samples lost {res['samples_lost']}, "
            f"host load {load[0]:.1f}; host real-time wake-ups > 1 ms late: {hw['late_over_1ms']} "
            f"(max {hw['max_late_ms']:.1f} ms), overrun events during them {hw['overrun_events_during_host_stalls']}"
            f"/{hw['overrun_events']}")
    out = {
        "latency_p99": {"us": p99_us, "baseline_us": py_us, "ratio": py_us / p99_us, "note": note,
                        "cpu_percent": res["cpu_percent"], "device_emulation_cpu_percent": dev,
                        "loop_thread_cpu_percent": thread, "process_cpu_percent": proc,
                        "overruns": res["overruns"], "frames": res["frames"],
                        "gyro_samples": res["gyro_samples"], "samples_lost": res["samples_lost"],
                        "step_wall_p99_ms": res["step_wall_p99_ms"], "mode_seconds": res["mode_seconds"],
                        "attitude_error_arcsec_1sigma": res["attitude_error_arcsec_1sigma"],
                        "floor_arcsec": res.get("floor_arcsec"),
                        "loop_steps": res["loop_steps"], "samples_per_step": sps,
                        "counters": {k: (len(v) if k == "mode_changes" else v) for k, v in res["counters"].items()},
                        "fifo_watermark": cfg.gyro.fifo_watermark,
                        "sample_age_at_step_ms_p50": res.get("sample_age_at_step_ms_p50"),
                        "sample_age_at_step_ms_p99": res.get("sample_age_at_step_ms_p99"),
                        "exposure_to_output_ms_p50": res.get("exposure_to_output_ms_p50"),
                        "load_average": load, "host_wakeups": hw},
        "host_us_per_gyro_sample": {
            "us": in_run_us, "baseline_us": per_sample_us, "ratio": per_sample_us / in_run_us,
            "wall_us": in_run_wall_us, "isolated_us": stage_us, "isolated_ratio": per_sample_us / stage_us,
            "isolated_paced_us": paced_us, "host_floor_us": floor_us, "host_floor_us_one_sample_per_wake": floor_1_us,
            "host_bare_call_us": bare_us,
            "samples_per_step": sps,
            "cpu_percent": res["cpu_percent"], "device_emulation_cpu_percent": dev,
            "loop_thread_cpu_percent": thread,
            "note": (f"gyro path after the FIFO read (batch kernel, output stage, sinks), {sps:.2f} samples per "
                     f"step: {in_run_us:.1f} µs CPU ({in_run_wall_us:.1f} µs wall, with other threads' turns) in the "
                     f"{duration:.0f} s real-time run, {stage_us:.1f} µs isolated back to back, {paced_us:.1f} µs "
                     f"isolated once per 2.5 ms on an idle host (cold caches), {floor_us:.1f} µs this host's "
                     f"floor at the run's schedule (one compiled call per wake-up and one record written per "
                     f"sample, asleep between; {floor_1_us:.1f} µs waking for every sample), {bare_us:.1f} µs for one "
                     f"bare compiled call per wake-up writing its records (no Python around it: the least "
                     f"any path with one numba call per FIFO batch costs here); "
                     f"baseline: the per-sample Python path it replaced, {per_sample_us:.1f} µs isolated; loop CPU "
                     f"{res['cpu_percent']:.1f} % of a core{dev_note}; host load {load[0]:.1f}")},
        "per_sample_predict": {"us": numba_us, "baseline_us": py_us, "ratio": py_us / numba_us,
                               "note": "MEKF predict + 12 star projections per gyro sample, numba vs py_func"},
    }
    if startup:
        cold = startup.get("cold", {}).get("total_s")
        cached = startup.get("cached", {}).get("total_s")
        if cold and cached:
            out["numba_startup"] = {"us": cached * 1e6, "baseline_us": cold * 1e6, "ratio": cold / cached,
                                    "note": f"loop start-up: cold {cold:.1f} s (compile), cached {cached:.2f} s"}
    return out
