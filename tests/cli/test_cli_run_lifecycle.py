"""``gyrostar run`` from start to end as a user meets it: a run that fails after start, the
same ``--out`` again, scenario acceptance, and Ctrl-C at start-up and mid-run (real
subprocesses of the console script, SIGINT sent to the process group as a terminal does)."""

import json
import os
import signal
import subprocess
import time

import pytest
from cli_helpers import GYROSTAR, gyrostar
from gyrostar.hil.config import default_config_path
from gyrostar.recording import logfile as lf


def _config(tmp_path, **changes):
    """The built-in flatsat config with ``section.key = value`` lines replaced."""
    lines, section = [], None
    for line in default_config_path().read_text().splitlines():
        if line.startswith("["):
            section = line.strip()[1:-1]
        key = line.split("=")[0].strip()
        if f"{section}.{key}" in changes:
            line = f"{key} = {changes[f'{section}.{key}']}"
        lines.append(line)
    path = tmp_path / "flatsat.toml"
    path.write_text("\n".join(lines) + "\n")
    return path


def _records(path):
    return [(lf.KIND_NAMES.get(r.kind), r.payload) for r in lf.read_records(path)]


def test_missing_device_leaves_no_folder_and_an_unfinished_log_is_kept_aside(tmp_path):
    out = tmp_path / "run"
    # a real device that is not there: refused before the run folder is made (no folder, no log)
    cfg = _config(tmp_path, **{"gyro.kind": '"i2c"', "gyro.i2c_bus": "97"})
    res = gyrostar(["run", "--config", cfg, "--out", out])
    assert res.returncode == 3 and "/dev/i2c-97" in res.stderr, res.stderr
    assert "Traceback" not in res.stderr
    assert not out.exists()
    # an unfinished run's log in --out (no summary.json) is kept aside, the new run goes ahead
    out.mkdir()
    (out / "flatsat.gslog").write_bytes(b"an unfinished run's log")
    res = gyrostar(["run", "--fast", "--duration", "1", "--no-plots", "--out", out])
    assert res.returncode == 0, res.stderr
    assert "flatsat.failed-1.gslog" in res.stderr
    assert (out / "flatsat.failed-1.gslog").read_bytes() == b"an unfinished run's log"
    assert (out / "summary.json").exists() and _records(out / "flatsat.gslog")[0][0] == "meta"
    # a finished run is never overwritten
    res = gyrostar(["run", "--fast", "--duration", "1", "--out", out])
    assert res.returncode == 2 and "finished run" in res.stderr


SCENARIO = """name = "acc"
duration_s = 2.0
segments = [{{ seconds = 2.0 }}]
max_error_arcsec_1sigma = {err}
min_track_fraction = 0.01
"""


@pytest.mark.parametrize("limit,code", [(0.001, 1), (1000.0, 0)])
def test_scenario_acceptance_is_applied(tmp_path, limit, code):
    scen = tmp_path / "acc.toml"
    scen.write_text(SCENARIO.format(err=limit))
    res = gyrostar(["run", "--fast", "--scenario", scen, "--out", tmp_path / "r", "--no-plots", "--json"])
    assert res.returncode == code, res.stderr
    summary = json.loads(res.stdout)
    checks = summary["acceptance"]["checks"]
    assert summary["acceptance"]["applied"] and summary["exit_code"] == code
    err = summary["attitude_error_arcsec_1sigma"]
    assert checks["max_error_arcsec_1sigma"]["value"] == err and checks["max_error_arcsec_1sigma"]["pass"] == (
        err <= limit)
    assert checks["min_track_fraction"]["pass"]
    if code:
        line = [ln for ln in res.stderr.splitlines() if "acceptance failed" in ln]
        assert len(line) == 1 and "max_error_arcsec_1sigma" in line[0] and "min_track_fraction" not in line[0]
    assert json.loads((tmp_path / "r" / "summary.json").read_text())["acceptance"] == summary["acceptance"]


def test_shortened_run_judged_only_on_lost_samples_and_reaching_track(tmp_path):
    """The error limit describes the whole scenario: a shorter run is not judged on it, but it
    must still reach TRACK and lose no gyro samples."""
    scen = tmp_path / "acc.toml"
    scen.write_text(SCENARIO.format(err=0.001))
    res = gyrostar(["run", "--fast", "--scenario", scen, "--duration", "1", "--out", tmp_path / "r", "--no-plots",
                    "--json"])
    assert res.returncode == 0, res.stderr
    acc = json.loads(res.stdout)["acceptance"]
    assert acc["applied"] and "shorter" in acc["note"]
    assert set(acc["checks"]) == {"max_samples_lost", "reached_track"} and all(
        c["pass"] for c in acc["checks"].values())


def _interrupt(tmp_path, ready, extra=(), sig=signal.SIGINT, group=None, again_after=None):
    """Start ``gyrostar run`` in its own process group, wait for ``ready(out)``, send SIGINT
    to the group (as a terminal's Ctrl-C does) or SIGTERM to the main process only (as
    ``kill PID`` does; ``group=True``: to the group, as a service manager stopping its cgroup
    does), once more ``again_after`` s later if given, and return (result, out, seconds to
    ready)."""
    out = tmp_path / "run"
    p = subprocess.Popen([GYROSTAR, "run", "--duration", "60", "--out", str(out), *extra], stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True, start_new_session=True, stdin=subprocess.DEVNULL)
    t0 = time.monotonic()
    try:
        while not ready(out):
            assert p.poll() is None, p.communicate()
            assert time.monotonic() - t0 < 90, "run never got ready"
            time.sleep(0.01)
        waited = time.monotonic() - t0
        to_group = sig == signal.SIGINT if group is None else group
        for k in range(1 if again_after is None else 2):
            if k:
                time.sleep(again_after)
            if to_group:
                os.killpg(p.pid, sig)
            else:
                os.kill(p.pid, sig)
        stdout, stderr = p.communicate(timeout=60)
    finally:
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGKILL)
            p.wait()
    return subprocess.CompletedProcess(p.args, p.returncode, stdout, stderr), out, waited


def _one_interrupt_line(res, word="interrupted"):
    assert res.returncode == 130, res.stderr
    for bad in ("Traceback", "SystemError", "KeyboardInterrupt"):
        assert bad not in res.stderr and bad not in res.stdout, res.stderr
    lines = [ln for ln in res.stderr.splitlines() if word in ln]
    assert len(lines) == 1, res.stderr
    return lines[0]


def test_ctrl_c_during_start_up(tmp_path):
    """SIGINT while numba loads and the devices start: one line, exit 130, the log says why."""
    res, out, _ = _interrupt(tmp_path, lambda out: (out / "flatsat.gslog").exists())
    _one_interrupt_line(res)
    recs = _records(out / "flatsat.gslog")
    assert recs[0][0] == "meta"
    assert any(k == "event" and json.loads(p).get("aborted") == "interrupted" for k, p in recs)
    assert not (out / "summary.json").exists()


@pytest.mark.parametrize("to_thread", [False, True])
def test_ctrl_c_held_while_the_log_is_created_is_recorded(tmp_path, monkeypatch, to_thread, ctrl_c_raises,
                                                          wait_signal_held):
    """A Ctrl-C that arrives while the log and its META come into being is held until META is
    on disk, then delivered where the log records it: the log says the run was interrupted
    (once the held signal was delivered outside that guard and the log said nothing). The
    kernel gives a process-directed signal to any thread that does not block it (a library's
    worker, a test session's leftovers); ``to_thread`` sends it to such a thread: a hold by
    signal mask let it through at once there (a full test session failed that way)."""
    import threading

    from gyrostar.hil import config as hc
    from gyrostar.hil.runner import run_flatsat

    stop = threading.Event()
    other = threading.Thread(target=stop.wait, daemon=True)
    other.start()
    flush = lf.LogWriter.flush

    def flush_then_ctrl_c(self):
        flush(self)
        if not getattr(self, "_interrupted", False):
            self._interrupted = True
            if to_thread:
                signal.pthread_kill(other.ident, signal.SIGINT)
            else:
                os.kill(os.getpid(), signal.SIGINT)     # held here until the guard lifts
            assert wait_signal_held()   # recorded by the run's hold, not raised here

    monkeypatch.setattr(lf.LogWriter, "flush", flush_then_ctrl_c)
    try:
        with pytest.raises(KeyboardInterrupt):
            run_flatsat(hc.load_flatsat(), hc.load_scenario("demo"), duration=1.0, seed=1,
                        folder=tmp_path / "run", plots=False, status=False, fast=True)
    finally:
        stop.set()
    recs = _records(tmp_path / "run" / "flatsat.gslog")
    assert recs[0][0] == "meta"
    assert any(k == "event" and json.loads(p).get("aborted") == "interrupted" for k, p in recs)


def test_ctrl_c_mid_run_keeps_summary_and_plots(tmp_path):
    """SIGINT once the loop records outputs: summary.json and plots of the part that ran."""

    def running(out):
        log = out / "flatsat.gslog"
        return log.exists() and log.stat().st_size > 400_000     # outputs are being recorded

    res, out, waited = _interrupt(tmp_path, running)
    line = _one_interrupt_line(res)
    assert str(out) in line
    summary = json.loads((out / "summary.json").read_text())
    assert summary["interrupted"] is True and 0 < summary["ran_s"] < 60
    assert summary["outputs"] > 0 and summary["gyro_samples"] > 0
    for png in ("attitude_error.png", "latency_histogram.png"):
        assert (out / png).stat().st_size > 1000
    # the log is complete up to the interruption: it replays bit-exact
    rep = gyrostar(["replay", out / "flatsat.gslog", "--check", "--json"])
    assert rep.returncode == 0, rep.stderr
    assert json.loads(rep.stdout)["verdict"] == "bit-exact"


def test_second_ctrl_c_while_the_run_winds_up_keeps_the_summary(tmp_path):
    """Ctrl-C, and again 0.2 s later while the devices stop and the figures are computed: the
    second waits until summary.json is on disk (it may skip the plots), one line, exit 130."""

    def running(out):
        log = out / "flatsat.gslog"
        return log.exists() and log.stat().st_size > 400_000

    res, out, _ = _interrupt(tmp_path, running, again_after=0.2)
    _one_interrupt_line(res)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["interrupted"] is True and summary["outputs"] > 0
    rep = gyrostar(["replay", out / "flatsat.gslog", "--check", "--json"])
    assert rep.returncode == 0, rep.stderr


@pytest.mark.parametrize("group", [False, True])
def test_sigterm_mid_run_ends_like_ctrl_c(tmp_path, group):
    """``kill PID`` (SIGTERM to the main process) or SIGTERM to the whole process group (a
    service manager stopping the run's cgroup: the head emulator and link relay processes get
    it too): one line saying so, no traceback from any process, exit 130, the summary of the
    part that ran, a log that replays bit-exact."""

    def running(out):
        log = out / "flatsat.gslog"
        return log.exists() and log.stat().st_size > 400_000

    res, out, _ = _interrupt(tmp_path, running, sig=signal.SIGTERM, group=group)
    line = _one_interrupt_line(res, "terminated (SIGTERM)")
    assert str(out) in line
    summary = json.loads((out / "summary.json").read_text())
    assert summary["interrupted"] is True and 0 < summary["ran_s"] < 60
    rep = gyrostar(["replay", out / "flatsat.gslog", "--check", "--json"])
    assert rep.returncode == 0, rep.stderr
    assert json.loads(rep.stdout)["verdict"] == "bit-exact"


def test_ctrl_c_that_surfaces_as_another_exception_is_logged_as_an_interruption(tmp_path, monkeypatch):
    """A Ctrl-C inside numba's compiler surfaced as ``RuntimeError: no compiled object yet for
    <Library 'label_rest'>`` (a cold-cache start-up interrupted at 8 s): the CLI said
    "interrupted" (exit 130), the log said RuntimeError. The log now says it was interrupted
    and what surfaced."""
    from gyrostar.cli import interrupt
    from gyrostar.hil import config as hc
    from gyrostar.hil import runner

    def session_interrupted_in_native_code(*args, **kwargs):
        try:
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(1.0)                      # the handler raises here
        except KeyboardInterrupt:
            raise RuntimeError("no compiled object yet for <Library 'label_rest'>") from None

    monkeypatch.setattr(runner, "_session", session_interrupted_in_native_code)
    try:
        with interrupt.watch():
            with pytest.raises(RuntimeError):
                runner.run_flatsat(hc.load_flatsat(), hc.load_scenario("demo"), duration=1.0, seed=1,
                                   folder=tmp_path / "run", plots=False, status=False, fast=True)
            assert interrupt.seen()
    finally:
        with interrupt.watch():     # entering a watch forgets the signal: later tests start clean
            pass
    ev = [json.loads(p) for k, p in _records(tmp_path / "run" / "flatsat.gslog") if k == "event"]
    assert ev[-1]["aborted"] == "interrupted"
    assert ev[-1]["surfaced_as"].startswith("RuntimeError: no compiled object yet")


def test_a_failure_without_a_signal_is_logged_as_itself(tmp_path, monkeypatch):
    """Under the CLI's signal watch (as every ``gyrostar run`` is), no signal: the failure itself."""
    from gyrostar.cli import interrupt
    from gyrostar.hil import config as hc
    from gyrostar.hil import runner

    def session_fails(*args, **kwargs):
        raise RuntimeError("disk full")

    monkeypatch.setattr(runner, "_session", session_fails)
    with interrupt.watch(), pytest.raises(RuntimeError):
        runner.run_flatsat(hc.load_flatsat(), hc.load_scenario("demo"), duration=1.0, seed=1,
                           folder=tmp_path / "run", plots=False, status=False, fast=True)
    ev = [json.loads(p) for k, p in _records(tmp_path / "run" / "flatsat.gslog") if k == "event"]
    assert ev[-1] == {"aborted": "RuntimeError: disk full"}


def test_log_write_failure_stops_the_run_cleanly(tmp_path):
    """The disk takes no more (a file-size limit cuts the log at 2 MB, as a full disk would):
    one line naming the log and the reason, exit 3, no traceback from the writer thread;
    summary.json of the part that ran; the log replays bit-exact up to where it was cut."""
    import resource

    out = tmp_path / "full"
    limit = 2_000_000

    def cap():
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))

    res = subprocess.run([GYROSTAR, "run", "--fast", "--duration", "20", "--out", str(out), "--no-plots", "-q"],
                         capture_output=True, text=True, preexec_fn=cap, timeout=300, stdin=subprocess.DEVNULL)
    assert res.returncode == 3, res.stderr
    assert "Traceback" not in res.stderr and "Exception in thread" not in res.stderr, res.stderr
    lines = [ln for ln in res.stderr.splitlines() if "write failed" in ln]
    assert len(lines) == 1 and "flatsat.gslog" in lines[0] and "File too large" in lines[0], res.stderr
    assert (out / "flatsat.gslog").stat().st_size <= limit
    summary = json.loads((out / "summary.json").read_text())
    assert "write failed" in summary["log_error"] and 0 < summary["ran_s"] < 20
    rep = gyrostar(["replay", out / "flatsat.gslog", "--json"])
    assert rep.returncode == 0, rep.stderr
    rj = json.loads(rep.stdout)
    assert rj["verdict"] == "prefix" and rj["compared_outputs"] > 0
