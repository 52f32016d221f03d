"""A fast run's figure helpers (hil.figure_workers): the same PNGs, to the byte, as the
runner draws itself; a helper that cannot start, dies or is stopped costs only time."""

import subprocess

import numpy as np
import pytest
from gyrostar.hil import figure_workers as fw
from gyrostar.hil.plots import RUN_FIGURES, write_plots
from gyrostar.loop import record as R


@pytest.fixture(scope="module")
def run_outputs():
    """Outputs of a 30 s run at 400 Hz (TRACK with a COAST stretch), truth and centroid errors."""
    rng = np.random.default_rng(5)
    n = 12_000
    out = R.empty(n)
    out["t"] = 1000.0 + np.arange(n) / 400.0
    out["mode"] = R.MODE_TRACK
    out["mode"][:200] = R.MODE_ACQUIRE
    out["mode"][6000:7600] = R.MODE_COAST
    q = rng.normal(size=(n, 4)) * 1e-5
    q[:, 3] = 1.0
    out["q"] = q / np.linalg.norm(q, axis=1)[:, None]
    out["bias"] = 1e-5 + rng.normal(size=(n, 3)) * 1e-7
    out["omega"] = rng.normal(size=(n, 3)) * 1e-3
    cov = np.zeros((n, 6, 6))
    for i in range(6):
        cov[:, i, i] = 1e-10 * (1 + i)
    out["cov"] = cov
    out["n_stars"] = 12
    out["latency_us"] = rng.gamma(3.0, 50.0, n)
    truth = np.zeros(n, [("q", "f8", 4), ("bias", "f8", 3)])
    truth["q"][:, 3] = 1.0
    truth["bias"] = 1e-5
    cerr = np.c_[np.repeat(out["t"][::4], 12), rng.normal(size=(n // 4 * 12, 2)) * 0.1]
    return out, truth, cerr


@pytest.mark.parametrize("outputs_first", [False, True], ids=["all-at-once", "outputs-only-first"])
def test_helpers_draw_the_runners_figures_to_the_byte(tmp_path, run_outputs, outputs_first):
    """The same PNGs as the runner draws, whether every helper gets its job at once or the one
    whose figures need the outputs alone gets it first (the others wait for the truth and the
    centroid errors: :meth:`FigureWorkers.send_outputs_only`)."""
    out, truth, cerr = run_outputs
    here, there = tmp_path / "here", tmp_path / "helpers"
    here.mkdir()
    there.mkdir()
    mine = write_plots(here, out, truth, cerr, names=RUN_FIGURES)
    workers = fw.FigureWorkers().start()
    try:
        if outputs_first:
            workers.send_outputs_only(there, out)
            assert workers.sent == ([("latency_histogram", "overview")] if workers.planned is None else [])
        theirs = workers.draw(there, out, truth, cerr)
    finally:
        workers.close()
    assert workers.fallbacks == []
    assert [p.name for p in theirs] == [p.name for p in mine] == [f"{n}.png" for n in RUN_FIGURES]
    for a, b in zip(mine, theirs):
        assert a.read_bytes() == b.read_bytes(), a.name


def test_a_helper_that_died_is_drawn_by_the_runner(tmp_path, run_outputs):
    out, truth, cerr = run_outputs
    workers = fw.FigureWorkers().start()
    try:
        workers.procs[1].kill()
        workers.procs[1].wait()
        paths = workers.draw(tmp_path, out, truth, cerr)
    finally:
        workers.close()
    assert [p.name for p in paths] == [f"{n}.png" for n in RUN_FIGURES]
    assert all(p.stat().st_size > 10_000 for p in paths)
    assert len(workers.fallbacks) == 1 and workers.fallbacks[0].startswith("latency_histogram/overview: ")


def test_helpers_that_cannot_start_leave_the_figures_to_the_runner(tmp_path, run_outputs, monkeypatch):
    out, truth, cerr = run_outputs

    def no_process(*a, **k):
        raise OSError(11, "Resource temporarily unavailable")

    monkeypatch.setattr(subprocess, "Popen", no_process)
    workers = fw.FigureWorkers().start()
    paths = workers.draw(tmp_path, out, truth, cerr)
    workers.close()
    assert [p.name for p in paths] == [f"{n}.png" for n in RUN_FIGURES]
    assert workers.fallbacks == ["attitude_error/bias_estimate/centroid_error: could not start: "
                                 "[Errno 11] Resource temporarily unavailable",
                                 "latency_histogram/overview: could not start: "
                                 "[Errno 11] Resource temporarily unavailable"]


def test_a_helper_answers_an_error_as_one_json_line(tmp_path, run_outputs):
    """The helper's own protocol (``python -m gyrostar.hil.figure_workers``): a job whose
    folder cannot take the PNGs gets ``{"error": ...}`` naming it, exit 0, no traceback."""
    import json
    import pickle
    import sys

    out, truth, cerr = run_outputs
    not_a_folder = tmp_path / "not-a-folder"
    not_a_folder.write_text("")
    job = {"folder": str(not_a_folder), "names": fw.GROUPS[0], "out": out, "truth": truth, "centroid_err": cerr}
    proc = subprocess.run([sys.executable, "-m", "gyrostar.hil.figure_workers"], input=pickle.dumps(job),
                          capture_output=True, timeout=120)
    assert proc.returncode == 0 and b"Traceback" not in proc.stderr
    reply = json.loads(proc.stdout.decode().strip().splitlines()[-1])
    assert "not-a-folder" in reply["error"]


def test_close_ends_helpers_that_got_no_job():
    workers = fw.FigureWorkers().start()
    procs = list(workers.procs)
    workers.close()
    assert all(p.poll() is not None for p in procs)


def test_on_one_cpu_no_helper_starts_and_the_runner_draws(tmp_path, run_outputs, monkeypatch):
    out, truth, cerr = run_outputs
    monkeypatch.setattr(fw.host_cpus, "cpus", lambda: 1)
    workers = fw.FigureWorkers().start()
    assert workers.procs == ["one CPU", "one CPU"]
    paths = workers.draw(tmp_path, out, truth, cerr)
    workers.close()
    assert [p.name for p in paths] == [f"{n}.png" for n in RUN_FIGURES]
    assert workers.planned == "one CPU" and workers.fallbacks == []      # by design: nothing to warn of


def test_a_long_run_is_drawn_by_the_runner(tmp_path, run_outputs, monkeypatch):
    out, truth, cerr = run_outputs
    monkeypatch.setattr(fw, "HELPER_MAX_OUTPUTS", len(out) - 1)
    workers = fw.FigureWorkers().start()
    procs = list(workers.procs)
    paths = workers.draw(tmp_path, out, truth, cerr)
    workers.close()
    assert [p.name for p in paths] == [f"{n}.png" for n in RUN_FIGURES]
    assert workers.planned == f"a run of {len(out)} outputs" and workers.fallbacks == []
    assert all(p.poll() is not None for p in procs)      # ended, not left waiting for a job


@pytest.mark.parametrize("stdin, code, said", [(b"", 0, b""), (b"hello\n", 2, b"stdin holds no figure job")])
def test_a_helper_given_no_job_or_garbage(stdin, code, said):
    import sys

    proc = subprocess.run([sys.executable, "-m", "gyrostar.hil.figure_workers"], input=stdin, capture_output=True,
                          timeout=120)
    assert proc.returncode == code and proc.stdout == b""
    assert said in proc.stderr and b"Traceback" not in proc.stderr and len(proc.stderr.splitlines()) <= 1
