"""The Dask campaign: same per-run results for 1 and 2 workers; the network rules."""

import socket
import subprocess
import sys

import pytest
from gyrostar.errors import ConfigError, DeviceError
from gyrostar.hil.eval_loop import run_seeds
from gyrostar.hil.montecarlo import campaign
from gyrostar.hil.montecarlo.campaign import Cluster, is_loopback, results_sha256, run_campaign


@pytest.mark.slow
def test_results_do_not_depend_on_the_worker_count():
    seeds = run_seeds(9, 2)
    with Cluster(1) as c1:
        one = run_campaign(c1, seeds, 10.0)
    with Cluster(2) as c2:
        two = run_campaign(c2, seeds, 10.0)
    assert not any(r["failed"] for r in one), [r["reason"] for r in one]
    assert [r["seed"] for r in one] == seeds
    assert results_sha256(one) == results_sha256(two)
    # the runs really ran: outputs at 400 Hz for the whole run
    assert all(r["outputs"] >= 0.99 * 400 * 10.0 for r in one)


@pytest.mark.parametrize("address,loop", [("tcp://127.0.0.1:8786", True), ("localhost:8786", True),
                                          ("tcp://[::1]:8786", True), ("tcp://10.0.0.5:8786", False),
                                          ("tls://scheduler.example:8786", False)])
def test_loopback_rule(address, loop):
    assert is_loopback(address) is loop


def test_remote_scheduler_without_tls_is_refused():
    with pytest.raises(ConfigError, match="only over TLS"):
        Cluster(scheduler="tcp://192.0.2.10:8786")


def test_a_scheduler_that_does_not_answer_is_one_line(monkeypatch):
    monkeypatch.setattr(campaign, "CONNECT_TIMEOUT_S", 1.0)
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    with pytest.raises(DeviceError, match="no Dask scheduler answered"):
        Cluster(scheduler=f"tcp://127.0.0.1:{port}")


def test_cli_rejects_bad_arguments_in_one_line():
    for args, text in ((["--runs", "0"], "--runs"), (["--duration", "5"], "--duration"),
                       (["--duration", "1e5"], "--duration"), (["--tls-ca", "x.pem"], "go together")):
        p = subprocess.run([sys.executable, "-m", "gyrostar.cli.main", "eval", "loop", *args],
                           capture_output=True, text=True, timeout=60)
        assert p.returncode == 2, p.stderr
        assert text in p.stderr and "Traceback" not in p.stderr
        assert len(p.stderr.strip().splitlines()) == 1


def test_local_workers_are_capped_at_the_runs_and_the_cpus(monkeypatch, caplog):
    from gyrostar.hil import eval_loop

    monkeypatch.setattr("gyrostar.hil.host_cpus.cpus", lambda: 2)
    with caplog.at_level("WARNING", logger="gyrostar"):
        assert eval_loop.local_workers(1000, 2) == 2          # 1000 processes for two runs: two
        assert "--workers 1000 capped at 2 (2 runs, 2 CPUs)" in caplog.text
        assert eval_loop.local_workers(1000, 50) == 2         # ... and never more than the CPUs
        assert eval_loop.local_workers(3, 1) == 1
    assert eval_loop.local_workers(2, 10) == 2
    with pytest.raises(ConfigError, match="--workers"):
        eval_loop.local_workers(0, 10)


def test_progress_lines_off_a_terminal(caplog):
    """Off a terminal the campaign prints a line as runs finish (at most one per interval, and
    the last), not nothing until the end."""
    from gyrostar.hil.eval_loop import ProgressLines

    now = [0.0]
    lines = ProgressLines(4, every_s=10.0, clock=lambda: now[0])
    with caplog.at_level(25, logger="gyrostar"):     # NOTICE
        for t, failed in ((5.0, 0), (8.0, 1), (20.0, 1), (21.0, 1)):
            now[0] = t
            lines.done(failed)
    msgs = [r.getMessage() for r in caplog.records]
    assert msgs == ["loop Monte Carlo: 1 of 4 runs done, 0 failed, 5 s so far, about 15 s left",
                    "loop Monte Carlo: 3 of 4 runs done, 1 failed, 20 s so far, about 7 s left",
                    "loop Monte Carlo: 4 of 4 runs done, 1 failed, 21 s so far, about 0 s left"]


def test_closed_dask_connections_leave_no_traceback_on_stop(caplog):
    """SIGTERM to eval loop printed asyncio's 'Future exception was never retrieved' with a
    CommClosedError traceback per closed stream: dropped; other asyncio errors still show."""
    import logging

    from distributed.comm.core import CommClosedError
    from gyrostar.hil.dask_quiet import silence_logs
    from tornado.iostream import StreamClosedError

    silence_logs()
    log = logging.getLogger("asyncio")
    for exc in (CommClosedError("in <TCP (closed) Scheduler Broadcast>: Stream is closed"), ValueError("real")):
        try:
            try:
                raise StreamClosedError() if isinstance(exc, CommClosedError) else KeyError("x")
            except Exception as inner:
                raise exc from inner
        except Exception as caught:
            log.error("Future exception was never retrieved", exc_info=(type(caught), caught, caught.__traceback__))
    shown = [r for r in caplog.records if r.name == "asyncio"]
    assert len(shown) == 1 and shown[0].exc_info[1].args == ("real",)
