"""``gyrostar run``: the coupled loop on a flatsat (built-in simulated one by default).

A run folder (``gyrostar.paths.runs_dir()/<timestamp>_<scenario>`` or ``--out``) receives:

* ``flatsat.gslog`` — the log (raw link frames both ways, gyro bus transactions, clock
  readings, outputs, truth); ``gyrostar replay`` feeds it back through the same driver;
* ``summary.json`` — the figures printed at the end (also ``--json`` on stdout);
* ``attitude_error.png``, ``centroid_error.png``, ``bias_estimate.png``,
  ``latency_histogram.png`` (unless ``--no-plots``).

Every flatsat runs on the host monotonic clock: the head emulator's and the firmware's
exposures take their real time, so a simulated flatsat runs in real time as well; the loop
is paced every gyro period by a drift-free scheduler, and the head worker's Python work is
kept between steps (:class:`gyrostar.loop.scheduler.StepGate`). ``--realtime`` also asks
for the config's SCHED_FIFO priority / CPU affinity (when permitted; see
:mod:`gyrostar.realtime`). Latency is host time from a gyro FIFO read to the emitted
outputs; ``cpu_percent`` is the loop thread's CPU time per wall second.
"""

from __future__ import annotations

import json
import logging
import time
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

from ..cli import interrupt
from ..cli.output import emit
from ..errors import ConfigError
from ..paths import runs_dir
from . import acceptance
from . import config as hc

log = logging.getLogger(__name__)
FAST_NOT_REALTIME = "--fast runs on a simulated clock: it cannot be combined with --realtime or a probe"


def make_run_folder(out: str | None, scenario: str):
    """The run folder and its held run lock (:mod:`gyrostar.hil.run_folder`): ``--out``
    (created), or a fresh ``runs/<UTC time>_<scenario>``.

    A folder another run is using (its lock held) is refused. An ``--out`` that holds a
    finished run (``summary.json``) is refused. One that holds only an unfinished run's log
    (no summary: the run failed or was killed) is reused, the old log moved aside to
    ``flatsat.failed-N.gslog`` (never deleted), and a warning says so."""
    from .run_folder import lock_run_folder

    if out:
        folder = Path(out)
        try:
            folder.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise ConfigError(f"--out {folder}: cannot create the run folder: {exc.strerror or exc}") from exc
        lock = lock_run_folder(folder)      # before anything in it is looked at or moved
        if (folder / "summary.json").exists():
            lock.release()
            raise ConfigError(f"--out {folder} already holds a finished run (summary.json); choose another --out")
        old = folder / "flatsat.gslog"
        if old.exists():
            n = 1
            while (folder / f"flatsat.failed-{n}.gslog").exists():
                n += 1
            kept = folder / f"flatsat.failed-{n}.gslog"
            old.rename(kept)
            log.warning("--out %s held an unfinished run's log (no summary.json): kept as %s", folder, kept.name)
        return folder, lock
    stamp = datetime.now(UTC).strftime("%Y%m%dT%H%M%S")
    base = runs_dir() / f"{stamp}_{scenario}"
    folder = base
    i = 1
    while True:
        try:
            folder.mkdir(parents=True)      # two runs started in the same second each get their own
            break
        except FileExistsError:
            folder = Path(f"{base}_{i}")
            i += 1
    return folder, lock_run_folder(folder, "run folder")


def run(args) -> int:
    t_command = time.perf_counter()      # the start-up (compiling, star index) counts in command_wall_s
    cfg = hc.load_flatsat(getattr(args, "config", None))
    if getattr(args, "calibration", None):
        cfg.calibration = str(args.calibration)
    from .flatsat import emulated_head, preflight

    scen = hc.load_scenario(getattr(args, "scenario", None) or ("demo" if emulated_head(cfg) else "bench"))
    preflight(cfg, scen, simulated_clock=bool(getattr(args, "fast", False)))   # devices too: before any run folder
    from ..loop.warmup import note_cold_start
    from ..paths import check_cache_writable

    check_cache_writable()          # exit 2 naming it, before a minute of compiling
    note_cold_start()
    duration = scen.duration_s if getattr(args, "duration", None) is None else float(args.duration)
    if not (duration > 0 and np.isfinite(duration)):
        raise ConfigError(f"--duration must be a finite number of seconds > 0, got {duration}")
    if getattr(args, "fast", False) and getattr(args, "realtime", False):     # refused before the run folder is made
        raise ConfigError(FAST_NOT_REALTIME)
    from .run_memory import check_kept_outputs_fit

    check_kept_outputs_fit(duration, cfg.gyro.odr_hz)     # before the run folder is made
    from .view.feed import ViewFeed, check, options_from

    view_opts = options_from(args)
    view = None
    if view_opts is not None:
        if not cfg.outputs.record:
            raise ConfigError("--view, --view-save and --view-serve ride on the run's log: the config sets "
                              "outputs.record = false")
        check(view_opts)      # rerun-sdk, a display, the recording's path: before the run folder is made
        view = ViewFeed(view_opts, lossless=bool(getattr(args, "fast", False)))
    # the lock is held until this function returns (the run, its summary and figures written)
    folder, lock = make_run_folder(getattr(args, "out", None), scen.name)     # noqa: F841 - held, not used
    try:
        result = run_flatsat(cfg, scen, duration=duration, seed=int(getattr(args, "seed", 1) or 0), folder=folder,
                             realtime=bool(getattr(args, "realtime", False)),
                             plots=not getattr(args, "no_plots", False),
                             status=getattr(args, "verbose", 0) >= 0,
                             config_path=getattr(args, "config", None), fast=bool(getattr(args, "fast", False)),
                             view=view, panel=_panel_wanted(args))
    except BaseException:
        if view is not None:
            view.abort()
        raise
    result["command_wall_s"] = round(time.perf_counter() - t_command, 2)
    _warn_losses(result)
    code = _report(args, cfg, scen, duration, folder, result)
    if view is not None:
        if result.get("interrupted"):
            view.abort()
        else:
            view.serve_until_interrupted()     # --view-serve: the web viewer stays up until Ctrl-C
    return code


def _panel_wanted(args) -> bool:
    """The live panel: on a terminal (stderr), not with --json or --quiet."""
    import sys

    return getattr(args, "verbose", 0) >= 0 and not getattr(args, "json", False) and sys.stderr.isatty()


def _report(args, cfg, scen, duration: float, folder: Path, result: dict) -> int:
    """Print a finished run's summary and say its exit code."""
    if result.get("log_error"):
        result["exit_code"] = 3
        emit(args, result, human_summary(result))
        where = (f"summary in {folder}" if not result.get("summary_error")
                 else f"summary.json not written either: {result['summary_error']}")
        log.error("%s (%.1f s of %.1f s ran; %s)", result["log_error"], result.get("ran_s") or 0.0, duration, where)
        return 3
    if result.get("interrupted"):
        result["exit_code"] = 130
        emit(args, result, human_summary(result))
        plotted = isinstance(result.get("plots"), list) and result["plots"]
        what = "the summary and plots of the part that ran are" if plotted else "the summary of the part that ran is"
        log.error("%s at %.1f s of %.1f s: %s in %s",
                  interrupt.reason(), result.get("ran_s") or 0.0, duration, what, folder)
        return 130
    acc = acceptance.evaluate(scen, result, duration)
    result["acceptance"] = acc
    failed = acceptance.failures(acc)
    result["exit_code"] = 1 if failed else 0
    _write_summary(folder, result)
    emit(args, result, human_summary(result))
    if failed:
        log.error("scenario acceptance failed: %s", "; ".join(failed))
        return 1
    return 0


def _warn_losses(result: dict) -> None:
    """A warning for what a run lost without stopping: gyro samples (the FIFO overflowed) and
    network outputs every one of whose datagrams the kernel refused."""
    lost = result.get("samples_lost") or 0
    if lost:
        why = ("on a simulated clock only a stall the scenario injects does that" if result.get("fast") else
               f"{result.get('overruns') or 0} overruns: a loaded host, swapping or a blocked disk; a simulated "
               "flatsat on a busy host keeps up with --fast")
        log.warning("%d gyro samples lost: the gyro FIFO overflowed while the loop was held off (%s); a fault to "
                    "investigate (docs/HARDWARE.md, Troubleshooting: Overruns)", lost, why)
    for key, what in (("udp", "UDP output"), ("space_packets", "space-packet output")):
        sent = result.get(key) or {}
        if sent and not sent.get("sent") and sent.get("dropped"):
            log.warning("%s to %s: every datagram (%d) was refused by the network; nothing was sent", what,
                        sent.get("to"), sent["dropped"])


def run_flatsat(cfg: hc.FlatsatConfig, scen: hc.Scenario, duration: float, seed: int, folder: Path,
                realtime: bool = False, plots: bool = True, status: bool = True, config_path=None,
                record: bool | None = None, on_output=None, probe=None, fast: bool = False,
                keep_arrays: bool = False, view=None, panel: bool = False) -> dict:
    """Run one flatsat session and return its summary (also written to summary.json).

    ``fast``: the emulated devices on a simulated clock in lock-step with the loop
    (:mod:`gyrostar.hil.lockstep`), as fast as the host computes; same loop, log and figures.

    ``probe``: a :class:`gyrostar.loop.wakeup_probe.WakeupProbe` to run beside the loop; the
    summary's ``host_wakeups`` then says how often the host itself woke a real-time task
    late and how many overruns coincided with that.

    ``view``: a :class:`gyrostar.hil.view.feed.ViewFeed` fed from the log writer (its figures in
    the summary's ``view``); ``panel``: the terminal panel instead of the status line."""
    from ..loop.record import describe
    from ..recording import logfile as lf

    record = cfg.outputs.record if record is None else record
    if fast and (realtime or probe is not None):
        raise ConfigError(FAST_NOT_REALTIME)
    from .run_memory import check_kept_outputs_fit

    check_kept_outputs_fit(duration, cfg.gyro.odr_hz)     # before a log or a device is touched
    from ..telemetry import timescale
    from . import flatsat

    calib = flatsat.load_calibration(cfg)
    log.info("calibration: %s", calib.describe())
    # fast mode: the simulated clock's start (flatsat.FAST_T0) is mapped to this instant
    timemap = timescale.from_pair(flatsat.FAST_T0, time.time()) if fast else timescale.capture()
    folder = Path(folder)
    meta = {"format": "gyrostar flatsat log 1", "config": _cfg_dict(cfg), "scenario": _cfg_dict(scen),
            "duration_s": duration, "seed": seed, "realtime": realtime, "fast": fast, "output": describe(),
            "started_utc": datetime.now(UTC).isoformat(), "calibration": calib.meta(), "time": timemap.meta(),
            "camera_sigma_px": flatsat.camera_sigma(cfg, scen, calib)}     # the σ this run's loop uses
    # the log file and its META record come into being together: a Ctrl-C in between is held
    # until META is on disk, so a log never exists without saying what run it was
    held = interrupt.SignalHold()

    try:
        folder.mkdir(parents=True, exist_ok=True)
        writer = lf.LogWriter(folder / "flatsat.gslog", background=True) if record else None
        if writer:
            writer.meta(meta)
            writer.flush()      # on disk before anything can fail: a failed run's log still says what it was
    except FileExistsError as exc:
        held.release()
        raise ConfigError(f"{folder} already holds a log (flatsat.gslog): choose another run folder") from exc
    except OSError as exc:
        held.release()
        raise ConfigError(f"run folder {folder}: {exc.strerror or exc}") from exc
    except BaseException:
        held.release()
        raise
    figures = None
    shown = None
    try:
        # a Ctrl-C held while the log came into being is delivered here, where the log records it
        held.release()
        if view is not None and writer is not None:
            # the view rides on the log: its META first, then every run of records the writer drains
            view.start()
            view.send_records([lf.Record(lf.META, 0, 0, json.dumps(meta, sort_keys=True).encode())])
            writer.tee = view.tee
        if plots and fast:
            # helpers that import matplotlib while the run starts up, then draw the figures side
            # by side (started with the loop instead, they slow it by more than they save; real
            # time leaves the host's second core to the loop's other threads: drawn after)
            from .figure_workers import FigureWorkers

            figures = FigureWorkers().start()
        res = _session(cfg, scen, duration, seed, folder, realtime, plots, status, writer, on_output, probe,
                       fast, keep_arrays, calib=calib, timemap=timemap, figures=figures, panel=panel)
    except BaseException as exc:
        if writer:
            # a Ctrl-C inside native code (numba compiling, a C extension) can surface as another
            # exception: the log says it was an interruption, as the CLI does, and what surfaced
            what = f"{type(exc).__name__}: {exc}"[:500]
            if isinstance(exc, KeyboardInterrupt):
                ev = {"aborted": "interrupted"}
            elif interrupt.seen():
                ev = {"aborted": "interrupted", "surfaced_as": what}
            else:
                ev = {"aborted": what}
            try:
                writer.event(ev)
            except ValueError:      # already closed: the failure came after the run's end
                pass
        raise
    finally:
        if figures is not None:
            figures.close()
        if writer:
            writer.close()
        if view is not None:
            shown = view.close()       # the view draws the log's last records (truth, summary) first
    if shown is not None:
        res["view"] = shown
        _write_summary(folder, res)
    return res


def _session(cfg, scen, duration, seed, folder, realtime, plots, status, writer, on_output, probe, fast,
             keep_arrays=False, calib=None, timemap=None, figures=None, panel=False) -> dict:
    """The body of :func:`run_flatsat` once its log holds the META record."""
    import sys

    from ..loop.floor import ARCSEC, pointing_bias_arcsec
    from ..loop.record import OUTPUT_DTYPE
    from ..loop.scheduler import PeriodicScheduler, StepGate, realtime_setup
    from ..loop.sinks import ArraySink, CallbackSink, RecorderSink, SpacePacketSink, UdpSink
    from ..recording import logfile as lf
    from . import flatsat
    from .analysis import summarize
    from .status import StatusLine, StatusPanel

    flatsat.preflight(cfg, scen, simulated_clock=fast)    # device nodes: exit 3 naming one that is not there
    # the loop shares the interpreter with the link reader and head worker threads (and
    # in-process emulators): switch threads often so the 400 Hz path is not held off
    if not fast:
        sys.setswitchinterval(0.0002)
    rt = None
    if realtime:
        rt = realtime_setup(cfg.realtime.sched_fifo_priority or None, cfg.realtime.cpus or None)

    from ..loop.coupled import warmup

    t_w = time.perf_counter()
    warm = warmup()
    warm["seconds"] = time.perf_counter() - t_w

    # every output of the run, for its figures: one array with room for the run at the gyro's ODR,
    # its pages touched as the run goes, between steps (ArraySink.reserve; run_memory checked it fits)
    try:
        kept = ArraySink(int(duration * cfg.gyro.odr_hz * 1.05) + 4096)
    except MemoryError:
        raise ConfigError(f"a run of {duration:g} s: no room for its outputs in memory (the kernel refused "
                          f"{duration * cfg.gyro.odr_hz * 1.05 * OUTPUT_DTYPE.itemsize / 1e9:.1f} GB of "
                          "address space): choose a shorter --duration") from None
    sinks = [kept]
    if on_output is not None:
        sinks.append(CallbackSink(on_output))
    if writer:
        sinks.append(RecorderSink(writer))
    udp = None
    if cfg.outputs.udp:
        udp = UdpSink(cfg.outputs.udp_host, cfg.outputs.udp_port, allow_remote=cfg.outputs.allow_remote)
        sinks.append(udp)
    tm = None
    if cfg.outputs.space_packets:
        tm = SpacePacketSink(cfg.outputs.tm_host, cfg.outputs.tm_port, timemap, apid=cfg.outputs.tm_apid,
                             allow_remote=cfg.outputs.allow_remote, frame_apid=cfg.outputs.tm_frame_apid)
        sinks.append(tm)

    fs = flatsat.build(cfg, scen, seed=seed, realtime=realtime, writer=writer, fast=fast, calibration=calib)
    if tm is not None:   # the frame packets carry the camera calibration's pointing bias
        bias = pointing_bias_arcsec(flatsat.camera_bias(fs.calibration), fs.camera.focal_length_px)
        tm.pointing_bias_rad = (bias[0] * ARCSEC, bias[1] * ARCSEC)
    loop = fs.make_loop(sinks)
    warm["identifier_s"] = loop.warm_identifier()
    import gc

    # everything allocated so far lives for the run: keep it out of the collector's passes
    # (a full collection over the start-up heap takes milliseconds, inside some step)
    gc.collect()
    gc.freeze()
    gc_thresholds = gc.get_threshold()
    if fast:
        # no step waits for a pause here: collect the young generation ten times less often
        gc.set_threshold(10 * gc_thresholds[0], *gc_thresholds[1:])
    wiring = fs.wiring
    line = StatusPanel(loop) if panel and status else StatusLine(enabled=status)
    step_wall: list[float] = []
    # the loop's CPU seconds in its steps, and (real time) the loop thread's with its idle ticks,
    # written by the runner as it goes (a run stopped early too)
    cpu_box: list = [None, None]
    t_wall0 = time.perf_counter()
    cpu0 = time.process_time()
    # the head worker's Python work stays out of the steps (it shares the interpreter lock)
    gate = fs.lockstep if fs.lockstep is not None else StepGate()
    sched = None
    interrupted = False
    log_failed = None
    hold = None
    if hasattr(loop.head, "step_gate") and not (fs.lockstep is not None and fs.lockstep.inline_jobs):
        loop.head.step_gate = gate
    try:
        interrupt.raise_if_seen()      # a Ctrl-C during start-up whose exception an import swallowed
        fs.start_scenario(fs.clock_now())
        if writer:
            writer.event({"scenario_t0": fs.truth.t_origin if fs.truth is not None else fs.clock_now()})
        loop.start()
        fs.start_faults(t_start_of(fs))
        # the runners tick every gyro period and step when the loop says a step is due (a FIFO
        # watermark of samples, or a frame measured): CoupledLoop.step_due
        period = 1.0 / loop.gyro.odr_hz
        try:
            # a Ctrl-C lands between steps: the log never holds a step's inputs without its outputs
            with interrupt.StepBoundary() as boundary:
                if fs.lockstep is not None:
                    loop.image.threaded = False      # centroid in the step: same result, no hand-over per frame
                    _run_lockstep(fs, loop, duration, period, step_wall, line if status else None, boundary,
                                  writer, cpu_box, kept)
                else:
                    sched = PeriodicScheduler(period)
                    _run_realtime(fs, loop, gate, sched, duration, step_wall, line if status else None, probe,
                                  boundary, writer, cpu_box, kept)
        except KeyboardInterrupt:       # Ctrl-C: stop here, keep and report the part that ran
            interrupted = True
        except lf.LogWriteError as exc:  # the disk took no more: stop, keep and report the part that ran
            log_failed = exc
        except Exception:               # a Ctrl-C that surfaced from native code as another exception
            if not interrupt.seen():
                raise
            interrupted = True
        cpu_loop, cpu_thread = cpu_box
        # from here to summary.json a second Ctrl-C or SIGTERM waits (raised once it is on disk)
        hold = interrupt.SignalHold()
    finally:
        gate.open()
        line.close()
        loop.close()
        fs.close()
        if rt is not None:
            from ..realtime import leave_realtime

            leave_realtime()
        for s in sinks:
            s.close()
        # the run's start-up heap goes back to the collector: a process that runs many
        # sessions (a Monte Carlo worker) must not keep every run's objects frozen forever
        gc.unfreeze()
        gc.set_threshold(*gc_thresholds)
    try:
        wall = time.perf_counter() - t_wall0
        cpu_proc = time.process_time() - cpu0
        out = kept.records
        plots = plots and log_failed is None           # a full disk: no figures (the log's line says why)
        if figures is not None and plots and len(out):
            figures.send_outputs_only(folder, out)     # those drawing from the outputs alone start now
        truth = fs.truth_rows(out["t"]) if len(out) else None
        if writer and truth is not None:
            writer.append_rows(lf.TRUTH, truth, t_ns=0)     # as many records as the size limit asks
        seen = _bias_seen_by_loop(truth, calib)     # the bias the loop estimates: after the calibration's
        cerr = None
        if plots and len(out):
            cerr = fs.centroid_errors(out) if truth is not None else None
            if figures is not None:
                figures.send(folder, out, seen, cerr)      # the helpers draw while the summary is made
        res = summarize(out, seen, loop.gyro.odr_hz)
        floor = loop.floor_summary()
        if truth is not None and len(out):
            from .analysis import mid_exposure_errors, nees_at_updates

            res.update(nees_at_updates(out, truth))
            res.update(mid_exposure_errors(out, fs.truth_rows))
        counters = loop.counters()
        # flatsat seconds the run covered (the whole duration unless it was stopped early)
        ran_s = float(out["t"][-1] - t_start_of(fs)) if len(out) and (interrupted or log_failed) else duration
        res_top = {
            "scenario": scen.name,
            "flatsat": cfg.name,
            "duration_s": duration,
            "attitude_error_arcsec_1sigma": res.get("attitude_error_arcsec_1sigma"),
            "floor_arcsec": floor.get("floor_arcsec"),
            "measured_over_floor": (res["attitude_error_arcsec_1sigma"] / floor["floor_arcsec"]
                                    if res.get("attitude_error_arcsec_1sigma") and floor.get("floor_arcsec") else None),
            "mid_exposure_error_arcsec_1sigma": res.get("mid_exposure_error_arcsec_1sigma"),
            "mid_exposure_error_arcsec_1sigma_at_rest": res.get("mid_exposure_error_arcsec_1sigma_at_rest"),
            "mid_exposure_smoothed_error_arcsec_1sigma": res.get("mid_exposure_smoothed_error_arcsec_1sigma"),
            "floor_mid_exposure_arcsec": floor.get("floor_mid_exposure_arcsec"),
            # the camera calibration's pointing bias, 1σ about camera x and y (principal point σ / f): a
            # constant error beside the covariance (which holds the filter's random error only)
            "pointing_bias_arcsec_1sigma": floor.get("pointing_bias_arcsec_1sigma"),
            "nees_after_update": res.get("nees_after_update"),
            "nees_before_update": res.get("nees_before_update"),
            "latency_p99_ms": res.get("latency_p99_ms"),
            # fast mode: loop CPU per second of flatsat time (the share of a core it needs in real time)
            "cpu_percent": (100.0 * cpu_loop / (ran_s if fast else wall)) if wall > 0 and ran_s > 0
            and cpu_loop is not None else None,
            # real time: the loop thread with the scheduler's ticks that found no step due (400 a
            # second wake it; the status line's drawing left out)
            "loop_thread_cpu_percent": 100.0 * cpu_thread / wall if wall > 0 and cpu_thread is not None
            and not fast else None,
            # of which inside the in-process emulated gyro (fake bus, register model, its truth): on a real
            # flatsat the kernel's I2C driver and a GPIO edge read take this part
            "device_emulation_cpu_percent": (100.0 * fs.device_cpu.cpu_s / (ran_s if fast else wall))
            if wall > 0 and ran_s > 0 and cpu_loop is not None and fs.device_cpu is not None else None,
            "overruns": sched.overruns if sched is not None else 0,
            "mode_seconds": res["mode_seconds"],
            "frames": counters["frames"],
            "gyro_samples": counters["gyro_samples"],
            "samples_lost": counters["samples_lost"],
            "host_us_per_gyro_sample": loop.host_us_per_gyro_sample(),            # CPU of the loop thread
            "host_us_per_gyro_sample_wall": loop.host_us_per_gyro_sample_wall(),  # + other threads' turns
        }
        res_top.update({k: v for k, v in res.items() if k not in res_top})
        if floor.get("floor_inputs"):
            res_top["floor_inputs"] = floor["floor_inputs"]
        res_top["step_wall_p99_ms"] = float(np.percentile(step_wall, 99)) * 1e3 if step_wall else None
        # steps the loop took (a tick every gyro period, a step when due: CoupledLoop.step_due)
        res_top["loop_steps"] = len(step_wall)
        res_top["samples_per_step"] = counters["gyro_samples"] / len(step_wall) if step_wall else None
        res_top["process_cpu_percent"] = 100.0 * cpu_proc / wall if wall > 0 else None
        res_top["wall_s"] = wall
        res_top["realtime"] = realtime
        res_top["fast"] = fast
        if fast:
            res_top["speedup"] = duration / wall if wall > 0 else None
        res_top["latency_clock"] = "host monotonic clock, FIFO read complete → output emitted" + (
            " (host compute time; the simulated clock stands still inside a step)" if fast else "")
        res_top["counters"] = counters
        client = getattr(loop.head, "client", None)
        if client is not None:
            res_top["link"] = dict(client.stats)
        if getattr(loop, "streaming", False):
            res_top.update(loop.stream_summary())
            res_top["stream"] = loop.head.stats()
            res_top["link_utilisation"] = res_top["stream"].get("link_utilisation")
            res_top["head_mode"] = "stream"
        else:
            res_top["head_mode"] = "request"
        port = loop.head
        if hasattr(port, "acquire"):
            # the lost-in-space image the port used: the head's spot list, or full frames (by
            # configuration, or because the firmware answered FIND_SPOTS with UNKNOWN_TYPE)
            res_top["acquisition_image"] = "full_frame" if port.acquire != "spots" or port.spots_unsupported \
                else "spots"
        res_top["calibration"] = {"path": calib.path, "sha256": calib.sha256} if calib.cal is not None else None
        from .health import health

        res_top["health"] = health(out, loop.gyro.odr_hz, counters, dict(client.stats) if client is not None else None)
        res_top["numba_startup"] = warm
        res_top["wiring"] = wiring
        if getattr(fs, "environment", None) is not None and fs.device_truth is not None:
            from .environment_report import environment_summary

            res_top["environment"] = environment_summary(fs.environment, fs.device_truth, fs.sim_preset,
                                                         fs.true_camera.as_array(), duration, fs.device_truth.t_origin)
        if rt is not None:
            res_top["realtime_setup"] = {"sched_fifo": rt.sched_fifo, "cpus": rt.cpus, "notes": rt.notes}
        if tm is not None:
            res_top["space_packets"] = {"sent": tm.sent, "frames_sent": tm.frames_sent, "dropped": tm.dropped,
                                        "to": f"{tm.addr[0]}:{tm.addr[1]}", "apid": tm.apid,
                                        "frame_apid": tm.frame_apid}
        t_first = float(out["t"][0]) if len(out) else timemap.monotonic_s
        res_top["time"] = {"clock": "host CLOCK_MONOTONIC (s); TAI/UTC from the start pair (docs/TELEMETRY.md)",
                           "first_output_monotonic_s": t_first, "first_output_tai_s": float(timemap.tai(t_first)),
                           "first_output_utc": timemap.utc_iso(t_first)[0], "tai_minus_utc_s": timemap.tai_minus_utc_s}
        if udp is not None:
            res_top["udp"] = {"sent": udp.sent, "dropped": udp.dropped, "to": f"{udp.addr[0]}:{udp.addr[1]}"}
        if probe is not None:
            from ..loop.wakeup_probe import LATE_S, coincident

            pr = probe.result()
            res_top["host_wakeups"] = {
                "probe_sched_fifo": pr["granted"], "probe_priority": probe.priority, "wakeups": pr["wakeups"],
                f"late_over_{LATE_S * 1e3:.0f}ms": len(pr["late_s"]), "max_late_ms": pr["max_s"] * 1e3,
                "overrun_events": len(sched.overrun_t),
                "overrun_events_during_host_stalls": coincident(np.array(sched.overrun_t), pr["late_t"], pr["late_s"])}
        from ..loop.record import MODE_TRACK

        res_top["track_regained"] = acceptance.track_regained(out["mode"], MODE_TRACK)
        res_top["run_folder"] = str(folder)
        if interrupted or log_failed is not None:
            res_top["interrupted"] = interrupted
            res_top["ran_s"] = ran_s if len(out) else 0.0
        if log_failed is not None:
            res_top["log_error"] = str(log_failed)
        if writer:
            if writer.error is None:
                writer.event({"summary": _jsonable(res_top)})
            writer.close()
            res_top["log"] = str(folder / "flatsat.gslog")
        # a disk that took no more of the log takes no summary either: said once, in the log's line
        summary_error = _write_summary(folder, res_top, quiet=log_failed is not None)
        if summary_error:
            res_top["summary_error"] = summary_error
    finally:
        late = bool(hold.held)     # a Ctrl-C while the run wound up: its summary is on disk now
        hold.held.clear()
        hold.release()
    try:
        if late:
            raise KeyboardInterrupt
        if log_failed is not None:
            res_top["plots"] = "skipped: the log's disk took no more"
        elif plots and len(out):
            from .plots import write_plots

            if cerr is not None and len(cerr):
                res_top["centroid_error_px_rms"] = float(np.sqrt(np.mean(cerr[:, 1:] ** 2)))
            if figures is not None:
                drawn = figures.collect(folder, out, seen, cerr)
                for why in figures.fallbacks:
                    log.warning("figure helper: %s; drawn here instead", why)
            else:
                drawn = write_plots(folder, out, seen, cerr)
            res_top["plots"] = [str(p) for p in drawn]
            _write_summary(folder, res_top)
    except KeyboardInterrupt:      # Ctrl-C while winding up or plotting: the summary stands, no plots
        res_top["interrupted"] = True
        res_top.setdefault("ran_s", ran_s)
        res_top["plots"] = "skipped: interrupted"
        _write_summary(folder, res_top)
    if keep_arrays:
        # for evaluations (gyrostar eval loop): the outputs, the truth at each, the scenario start, the camera
        res_top["arrays"] = {"out": out, "truth": truth, "t0": t_start_of(fs), "camera": fs.camera}
    return res_top


def _run_realtime(fs, loop, gate, sched, duration: float, step_wall: list, line, probe, boundary, writer,
                  cpu_box, kept) -> None:
    """Real time: a tick every gyro period on the monotonic clock, a loop step at each tick the
    loop says is due (:meth:`CoupledLoop.step_due`). The loop's CPU seconds in its steps go to
    ``cpu_box[0]`` after every step, and the thread's with its idle ticks (less the status
    line's drawing) to ``cpu_box[1]`` (a run stopped early keeps them). The keeping sink
    ``kept`` makes its next rows after a step, in the tick's slack (:meth:`ArraySink.reserve`)."""
    cpu = line_cpu = 0.0
    thread0 = time.thread_time()
    if probe is not None:
        probe.start(duration)
    sched.start()
    t_start = t_start_of(fs)
    try:
        while True:
            sched.wait()
            t = fs.clock_now() - t_start
            if t >= duration:
                break
            # an injected "loop does not read the FIFO" fault, or no step due at this tick
            if fs.loop_stalled(t) or not loop.step_due(t + t_start):
                sched.done()
                gate.loop_exit(sched.deadline)
                continue
            c0 = time.thread_time()
            w0 = time.perf_counter()
            gate.loop_enter()
            boundary.inside = True
            loop.step()
            step_wall.append(time.perf_counter() - w0)
            cpu += time.thread_time() - c0
            cpu_box[0] = cpu
            sched.done()
            gate.loop_exit(sched.deadline)
            boundary.step_done()
            kept.reserve()
            if writer is not None and writer.error is not None:
                raise writer.failure()
            if line is not None and loop.last_output is not None and line.due():
                # the truth row (an attitude integration) only when the line redraws, not every step
                l0 = time.thread_time()
                line.update(loop.last_output, fs.truth_at(loop.last_output["t"]), step_wall[-1] * 1e6,
                            sched.overruns, duration, t0=t_start)
                line_cpu += time.thread_time() - l0
    finally:
        cpu_box[1] = time.thread_time() - thread0 - line_cpu


def _run_lockstep(fs, loop, duration: float, period: float, step_wall: list, line, boundary, writer,
                  cpu_box, kept) -> None:
    """Fast mode: tick every gyro period of simulated time, step when the loop says a step is
    due (:meth:`CoupledLoop.step_due`). The head port's jobs (and
    a streaming port's turns) run at once on their own time line (:meth:`Lockstep.run_job`); a worker
    thread (other head ports) runs between steps at the simulated times its replies (or
    timeouts) are due. The loop's CPU seconds on this thread (its steps and the
    few µs of scheduling per step, not the head jobs') go to ``cpu_box[0]`` when it ends: the
    thread's CPU time less the inline jobs' time (:attr:`Lockstep.job_cpu_s`, read on the wall
    clock: nothing else of the run is busy while they run)."""
    lk = fs.lockstep
    clock = fs.base_clock
    head = loop.head
    lk.begin()
    t_start = t_start_of(fs)
    # the head port runs each job or stream turn at once on its own time (Lockstep.run_job): the
    # head's faults follow that time line; there is no worker to wake or settle
    inline = lk.inline_jobs
    lk.on_time = lambda t: fs.apply_head_faults(t - t_start)
    lk.on_time_due = lambda t: fs.head_faults_due(t - t_start)
    t_next = clock.now() + period
    cpu0 = time.thread_time()      # this thread runs only the loop and the schedule: one reading
    shown = time.perf_counter()
    try:
        while True:
            lk.horizon = t_next
            while not inline:
                w = lk.wake_time
                if w is None or w > t_next:
                    break
                lk.wake()
                lk.settle(head)
            if t_next - t_start >= duration:
                break
            if t_next > clock.now():
                clock.set(t_next)
            t = t_next - t_start
            t_next += period
            fs.apply_faults(t)
            # an injected "loop does not read the FIFO" fault, or no step due at this tick
            if fs.loop_stalled(t) or not loop.step_due(t + t_start):
                continue
            w0 = time.perf_counter()
            boundary.inside = True
            loop.step()
            step_wall.append(time.perf_counter() - w0)
            boundary.step_done()
            kept.reserve()
            if writer is not None and writer.error is not None:
                raise writer.failure()
            if not inline:
                lk.settle(head)
            if line is not None and loop.last_output is not None and w0 - shown > 0.2:
                shown = w0
                line.update(loop.last_output, fs.truth_at(loop.last_output["t"]), step_wall[-1] * 1e6, 0, duration,
                            t0=t_start)
    finally:
        # the loop's CPU: the head jobs ran on this thread too (the emulated head and its client)
        cpu_box[0] = time.thread_time() - cpu0 - lk.job_cpu_s


def _bias_seen_by_loop(truth, calib):
    """Truth rows whose ``bias`` is what the loop's bias state estimates: a calibration's gyro
    map ω_camera = M (ω_meas − b) leaves M (b_true − b) (rad/s, camera axes); without one, the
    gyro's own bias. The log keeps the gyro's truth as it is."""
    gm = calib.gyro_map() if truth is not None and calib is not None else None
    if gm is None:
        return truth
    m, b, _ = gm
    seen = truth.copy()
    seen["bias"] = (np.asarray(truth["bias"]) - b) @ np.asarray(m).T
    return seen


def _write_summary(folder: Path, res: dict, quiet: bool = False) -> str | None:
    """summary.json of a run; a disk that takes no more is logged (unless ``quiet``: the
    caller says it), not raised (the figures are printed all the same). Returns the reason it
    was not written, or None."""
    from ..files import whole_or_nothing

    try:
        with whole_or_nothing(folder / "summary.json") as part:     # a full disk leaves none, not 0 bytes
            part.write_text(json.dumps(_jsonable(res), indent=2))
    except OSError as exc:
        if not quiet:
            log.error("%s/summary.json not written: %s", folder, exc.strerror or exc)
        return str(exc.strerror or exc)
    return None


def t_start_of(fs) -> float:
    world = fs.device_truth or fs.truth
    return world.t_origin if world is not None else fs.clock_now()


def _cfg_dict(obj) -> dict:
    from .. import config as gconfig

    return gconfig.to_dict(obj)


def _jsonable(obj):
    from ..cli.output import json_safe

    return json_safe(obj)


def human_summary(r: dict) -> str:
    def f(v, fmt):
        return "n/a" if v is None else format(v, fmt)

    modes = ", ".join(f"{k} {v:.1f} s" for k, v in r["mode_seconds"].items())
    lines = [
        f"[bold]gyrostar run[/] — {r['scenario']} on {r['flatsat']}, "
        + (f"{r['ran_s']:.1f} s (interrupted) of {r['duration_s']:.1f} s" if r.get("interrupted")
           else f"{r['duration_s']:.1f} s") + " of flatsat time "
        f"({r['wall_s']:.1f} s wall{', real time' if r['realtime'] else ''}"
        + (f"; {r['command_wall_s']:.1f} s with start-up" if r.get("command_wall_s") else "") + ")",
        "  attitude error (cross-boresight, 1σ, TRACK): " + (
            f"{r['attitude_error_arcsec_1sigma']:.2f}″" if r.get("attitude_error_arcsec_1sigma") is not None
            else "never in TRACK" if "track_fraction" in r else "n/a (no simulator truth)")
        + f" (floor {f(r.get('floor_arcsec'), '.2f')}″); mid-exposure "
        f"{f(r.get('mid_exposure_error_arcsec_1sigma'), '.2f')}″ "
        f"(floor {f(r.get('floor_mid_exposure_arcsec'), '.2f')}″)"
        + (", camera pointing bias {:.2f}″ / {:.2f}″ (x / y, 1σ, from the calibration)".format(*pb)
           if (pb := r.get("pointing_bias_arcsec_1sigma")) and any(pb) else ""),
        f"  modes: {modes}",
        f"  frames {r['frames']}, gyro samples {r['gyro_samples']}, samples lost {r['samples_lost']}",
        f"  latency p99 {f(r['latency_p99_ms'], '.3f')} ms ({r['latency_clock']}), loop CPU "
        f"{f(r['cpu_percent'], '.1f')}{' %' if r['cpu_percent'] is not None else ''} of a core"
        + (f" ({r['device_emulation_cpu_percent']:.1f} % in the emulated gyro)"
           if r.get("device_emulation_cpu_percent") is not None else "")
        + (f", {r['loop_thread_cpu_percent']:.1f} % with its idle ticks"
           if r.get("loop_thread_cpu_percent") is not None else "") + ", "
        f"overruns {r['overruns']}",
        f"  numba start-up {r['numba_startup']['seconds']:.2f} s ({r['numba_startup']['cache_hits']} cached, "
        f"{r['numba_startup']['compiled']} compiled)",
    ]
    if r.get("head_mode") == "stream" and r.get("frame_rate_hz") is not None:
        lb = r.get("link_budget") or {}
        lines.append(f"  head stream: {r['frame_rate_hz']:.1f} frames/s, link {lb.get('preset', '?')} "
                     f"{100 * (r.get('link_utilisation') or 0):.0f} % used, exposure → output p50 "
                     f"{f(r.get('exposure_to_output_ms_p50'), '.1f')} ms, sample age at its step p50/p99 "
                     f"{f(r.get('sample_age_at_step_ms_p50'), '.1f')}/{f(r.get('sample_age_at_step_ms_p99'), '.1f')} "
                     f"ms; stars cut for the link in "
                     f"{lb.get('frames_stars_cut', 0)} frames, rate changes {len(lb.get('rate_changes', []))}")
    v = r.get("view")
    if v:
        lines.append(f"  view: {v['shown']}; {v.get('frames')} frames drawn, {v['dropped_chunks']} runs of records "
                     f"({v['dropped_bytes'] / 1e3:.0f} kB) dropped for the view"
                     + (f"; [red]{v['error']}[/]" if v.get("error") else ""))
    if r.get("acquisition_image"):
        spots = r["acquisition_image"] == "spots"
        lines.append("  lost-in-space image: " + ("the head's spot list (FIND_SPOTS)" if spots else "full frames"))
    if r.get("bias_error_dps_final") is not None:
        lines.append("  final bias error (°/s): " + " ".join(f"{v:+.4f}" for v in r["bias_error_dps_final"]))
    if r.get("centroid_error_px_rms") is not None:
        lines.append(f"  tracked-star centroid error RMS {r['centroid_error_px_rms']:.3f} px")
    h = r.get("health") or {}
    if h.get("outputs"):
        lines.append(f"  without truth: TRACK {100 * h['track_fraction']:.0f} %, {h['mode_switches']} mode switches, "
                     f"stars tracked median {h['stars_tracked_median']:.0f}, frames "
                     f"{h.get('frames_hz', 0):.1f} Hz, attitude 3σ (cross, median) "
                     f"{f(h.get('attitude_3sigma_arcsec_cross_median'), '.1f')}″, "
                     f"link errors {h['link_error_outputs']}"
                     + (f", head clock steps {h['head_clock_steps']}" if h.get("head_clock_steps") else ""))
    from .environment_report import summary_line

    if (env_line := summary_line(r)) is not None:
        lines.append(env_line)
    cal = r.get("calibration")
    lines.append(f"  calibration: {cal['path']} (sha256 {cal['sha256'][:16]})" if cal else
                 "  calibration: none (nominal camera and gyro mounting)")
    not_wired = [k for k, v in r.get("wiring", {}).items() if str(v).startswith("NOT WIRED")]
    for k in not_wired:
        lines.append(f"  [red]{k}: {r['wiring'][k]}[/]")
    if r.get("interrupted"):
        lines.append(f"  [yellow]interrupted after {r.get('ran_s', 0.0):.1f} s: figures cover the part that ran[/]")
    acc = r.get("acceptance")
    if acc:
        from .acceptance import failures

        if not acc["applied"]:
            lines.append(f"  scenario acceptance not applied: {acc['note']}")
        else:
            bad = failures(acc)
            ok = [k for k, c in acc["checks"].items() if c["pass"]]
            lines.append("  scenario acceptance: " + ("[red]FAIL " + "; ".join(bad) + "[/]" if bad else "PASS")
                         + (f" (passed: {', '.join(ok)})" if ok and bad else f" ({', '.join(ok)})" if ok else "")
                         + (f" ({acc['note']})" if acc["note"] else ""))
    lines.append(f"  run folder: {r['run_folder']}")
    return "\n".join(lines)
