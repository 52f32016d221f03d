"""One run per run folder: a second ``gyrostar run`` into a folder another run is using is
refused with one line (exit 2) and touches nothing of the first run (both used to exit 0, the
second renaming the first's still-open log and overwriting its summary and plots)."""

import fcntl
import json
import os
import signal
import subprocess
import time

from cli_helpers import GYROSTAR, gyrostar
from gyrostar.hil.run_folder import LOCK_NAME
from gyrostar.recording import logfile as lf


def _one_line(res):
    """The one error line (a first start's progress NOTE on the cold-start cache may come before it)."""
    lines = [ln for ln in res.stderr.splitlines() if ln.strip() and not ln.startswith("gyrostar: NOTE:")]
    assert "Traceback" not in res.stderr, res.stderr
    assert len(lines) == 1, res.stderr
    return lines[0]


def test_folder_locked_by_another_process_is_refused_and_left_alone(tmp_path):
    out = tmp_path / "run"
    out.mkdir()
    (out / "flatsat.gslog").write_bytes(b"the other run's open log")     # no summary: looks unfinished
    fd = os.open(out / LOCK_NAME, os.O_RDWR | os.O_CREAT)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)      # as a running gyrostar run holds it
        os.write(fd, b"4242\n")
        res = gyrostar(["run", "--fast", "--duration", "1", "--no-plots", "--out", out], timeout=60)
        line = _one_line(res)
        assert res.returncode == 2 and str(out) in line and "in use" in line and "4242" in line, res.stderr
        assert sorted(p.name for p in out.iterdir()) == [LOCK_NAME, "flatsat.gslog"]
        assert (out / "flatsat.gslog").read_bytes() == b"the other run's open log"
    finally:
        os.close(fd)


def test_two_runs_into_one_out_the_second_is_refused(tmp_path):
    """The issue's case: the same ``run --out X`` started twice while the first runs."""
    out = tmp_path / "run"
    first = subprocess.Popen([GYROSTAR, "run", "--fast", "--duration", "600", "--no-plots", "--out", str(out)],
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True,
                             stdin=subprocess.DEVNULL)
    try:
        t0 = time.monotonic()
        log = out / "flatsat.gslog"
        while not (log.exists() and log.stat().st_size > 400_000):       # its loop records outputs
            assert first.poll() is None, first.communicate()
            assert time.monotonic() - t0 < 400, "the first run never got going"
            time.sleep(0.05)
        second = gyrostar(["run", "--fast", "--duration", "1", "--no-plots", "--out", out], timeout=120)
        line = _one_line(second)
        assert second.returncode == 2 and "in use" in line and f"(process {first.pid})" in line, second.stderr
        assert not (out / "flatsat.failed-1.gslog").exists() and not (out / "summary.json").exists()
        os.killpg(first.pid, signal.SIGINT)
        _stdout, stderr = first.communicate(timeout=300)
    finally:
        if first.poll() is None:
            os.killpg(first.pid, signal.SIGKILL)
            first.wait()
    assert first.returncode == 130, stderr
    # the first run's log and summary are its own, where it wrote them (not moved aside as a dead run's)
    assert json.loads((out / "summary.json").read_text())["duration_s"] == 600
    recs = list(lf.read_records(out / "flatsat.gslog"))
    assert recs[0].kind == lf.META and json.loads(recs[0].payload)["duration_s"] == 600
    assert not (out / "flatsat.failed-1.gslog").exists()
    # the lock went with its holder
    fd = os.open(out / LOCK_NAME, os.O_RDWR)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    finally:
        os.close(fd)
