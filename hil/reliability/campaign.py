"""The coupled loop on the simulated flatsat under a timed fault schedule.

:func:`run_campaign` builds the built-in flatsat (head emulator in a child process, BMI088
register model behind a :class:`~gyrostar.mocks.faults.FaultyBus`), paces the loop every
gyro period on the host monotonic clock as ``gyrostar run`` does, switches the scheduled
faults on and off, and keeps per loop step (decimated to ``keep_hz``) a compact row of a
trace preallocated for the whole run — time, mode, flags, attitude, and the loop's
counters — so memory does not grow with the run length. Exceptions escaping
``loop.step()`` are caught, counted and kept (the loop must never raise).

The faults are the scenario's (:class:`gyrostar.hil.config.Fault`), applied by the
flatsat's own :class:`~gyrostar.hil.flatsat.FaultPlan` at each tick: ``link-corruption``
(reply-stream corruption, drops and garbage bursts, ``rate``/``drop_rate``/``garbage_rate``),
``head-disconnect`` (the head's pty closes for ``seconds`` and a new one opens),
``gyro-nack`` (every gyro bus transaction NACKs), ``gyro-fifo-overrun`` (the loop does not
run for ``seconds``: the FIFO overruns) and ``head-clock-step`` (the head MCU's clock jumps
by ``step_s`` at ``at_s``, the link open).
"""

from __future__ import annotations

import logging
import os
import time

import numpy as np

log = logging.getLogger(__name__)

TRACE_DTYPE = np.dtype([
    ("t", "<f8"), ("mode", "u1"), ("flags", "<u2"), ("q", "<f8", (4,)), ("frames", "<i8"),
    ("frames_failed", "<i8"), ("head_errors", "<i8"), ("head_reconnects", "<i8"), ("gyro_errors", "<i8"),
    ("samples_lost", "<i8"), ("overruns", "<i8"), ("link_corrupt", "<i8"), ("link_retries", "<i8"),
    ("link_clock_steps", "<i8"),
])
"""One row per kept loop step: last output (host s, mode, flags, q ICRS→body) and counters."""


def rss_bytes(pid: int | str = "self") -> int:
    """Resident set size of a process (bytes), from /proc/<pid>/statm."""
    with open(f"/proc/{pid}/statm") as fh:
        return int(fh.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")


def run_campaign(faults, duration: float, seed: int = 1, keep_hz: float = 400.0, segments=None,
                 rss_every_s: float = 60.0, progress=None, cfg=None) -> dict:
    """Run the loop for ``duration`` s of flatsat time under ``faults`` (scenario faults,
    :class:`gyrostar.hil.config.Fault`, each validated).

    Returns ``{"trace", "truth", "counters", "link", "overruns", "steps", "exceptions", "rss",
    "byte_faults", "wall_s"}``: ``trace`` (:data:`TRACE_DTYPE`), ``truth`` (simulator truth
    at the trace times), ``rss`` rows ``[t, rss_self_bytes, rss_emulator_bytes]``.
    """
    from ...loop.coupled import warmup
    from ...loop.scheduler import PeriodicScheduler
    from .. import config as hc
    from .. import flatsat

    cfg = cfg or hc.load_flatsat(None)
    segs = segments or [hc.Segment(seconds=duration, rate_dps=(0.3, 0.2, 0.05))]
    for f in faults:
        f.validate()
    scen = hc.Scenario(name="reliability", duration_s=duration, segments=segs, faults=list(faults))
    warmup()
    fs = flatsat.build(cfg, scen, seed=seed, realtime=False, writer=None)
    if getattr(fs.irq, "model", None) is not None:
        fs.irq.model.truth_log = False   # (build does this too) the model's test-truth log grows ~90 kB/s
    plan = fs.faults
    n_keep = int(duration * keep_hz) + 16
    trace = np.empty(n_keep, TRACE_DTYPE)
    trace.view(np.uint8)[:] = 0      # touch every page now: RSS must not grow as the trace fills
    rss = np.zeros((int(duration / rss_every_s) + 4, 3))
    state = {"n": 0, "next_keep": -np.inf, "last": None}
    keep_dt = 1.0 / keep_hz
    exceptions: list[str] = []
    n_exc = 0
    n_rss = 0

    def keep(records):
        state["last"] = records[-1]

    from ...loop.sinks import CallbackSink

    loop = fs.make_loop([CallbackSink(keep)])
    loop.warm_identifier()
    sched = PeriodicScheduler(1.0 / cfg.gyro.odr_hz)
    emu_pid = plan.head_emulator.proc.pid
    wall0 = time.perf_counter()
    try:
        fs.truth.restart(fs.clock_now())
        loop.start()
        sched.start()
        t_start = fs.truth.t_origin
        next_rss = 0.0
        while True:
            sched.wait()
            t = fs.clock_now() - t_start
            if t >= duration:
                break
            fs.apply_faults(t)
            if t >= next_rss and n_rss < len(rss):
                rss[n_rss] = (t, rss_bytes(), rss_bytes(emu_pid))
                n_rss += 1
                next_rss += rss_every_s
                if progress is not None:
                    progress(t, loop)
            if not fs.loop_stalled(t) and loop.step_due(t + t_start):
                try:
                    loop.step()
                except Exception as exc:  # noqa: BLE001 - the campaign counts what escapes the loop
                    n_exc += 1
                    if len(exceptions) < 20:
                        exceptions.append(f"{t:.3f} s: {type(exc).__name__}: {exc}")
                    log.exception("loop.step raised")
            sched.done()
            last = state["last"]
            if last is not None and last["t"] >= state["next_keep"] and state["n"] < n_keep:
                state["next_keep"] = last["t"] + 0.999 * keep_dt
                c = loop.c
                client = getattr(loop.head, "client", None)     # replaced on reconnect: stats restart
                ls = client.stats if client is not None else {}
                trace[state["n"]] = (last["t"], last["mode"], last["flags"], last["q"], c.frames, c.frames_failed,
                                     c.head_errors, c.head_reconnects, c.gyro_errors, c.samples_lost,
                                     sched.overruns, ls.get("corrupt", 0), ls.get("retries", 0),
                                     ls.get("clock_steps", 0))
                state["n"] += 1
        plan.close()
        rss[n_rss] = (t, rss_bytes(), rss_bytes(emu_pid))
        n_rss += 1
    finally:
        loop.close()
        fs.close()
    trace = trace[: state["n"]]
    truth = fs.truth.rows(trace["t"])
    client = getattr(loop.head, "client", None)
    return {"trace": trace, "truth": truth, "t_origin": t_start, "counters": loop.counters(),
            "link": dict(client.stats) if client is not None else {}, "overruns": sched.overruns,
            "steps": sched.steps, "exceptions": exceptions, "n_exceptions": n_exc, "rss": rss[:n_rss],
            "byte_faults": plan.byte_counts, "gyro_bus": dict(plan.gyro_bus.injected),
            "wall_s": time.perf_counter() - wall0}


def cross_boresight_error_arcsec(trace: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """|δθ_xy| (arcsec) of each trace row's attitude against the truth (NaN where invalid)."""
    from ...loop.record import FLAG_ATTITUDE_VALID
    from ..analysis import ARCSEC, quat_error_angles_many

    e = quat_error_angles_many(trace["q"], truth["q"]) * ARCSEC
    err = np.hypot(e[:, 0], e[:, 1])
    err[(trace["flags"] & FLAG_ATTITUDE_VALID) == 0] = np.nan
    return err


def mode_seconds(t: np.ndarray, mode: np.ndarray, rows: np.ndarray | None = None) -> dict:
    """Seconds in each mode over the trace ``rows`` (bool mask; None: all): each row's mode
    holds until the next row's time (rows come one per loop step, whatever samples it took)."""
    from ...loop.record import MODE_NAMES

    held = np.diff(t, append=t[-1]) if len(t) else np.zeros(0)
    if rows is None:
        rows = np.ones(len(t), bool)
    return {name: round(float(held[rows & (mode == m)].sum()), 2) for m, name in MODE_NAMES.items()}
