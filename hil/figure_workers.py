"""A run's figures drawn by two helper processes beside the runner (``gyrostar run --fast``).

The helpers start with the run and import matplotlib while it starts up (0.3 s of a 60 s
fast run's wall time otherwise); when the loop has ended each is sent the outputs its
figures need and draws them, side by side with the other. A helper that cannot start,
fails or falls silent costs nothing but time: the runner draws its figures itself
(:func:`gyrostar.hil.plots.write_plots`), so a run's figures never depend on it.

Run as ``python -m gyrostar.hil.figure_workers``: one job (a pickle on stdin), one JSON
line on stdout (``{"paths": [...]}`` or ``{"error": "..."}``).
"""

from __future__ import annotations

import json
import os
import pickle
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from . import host_cpus
from .plots import RUN_FIGURES, figure_fields, write_plots

# the figures each helper draws: about the same time each on a run's outputs
GROUPS = (("attitude_error", "bias_estimate", "centroid_error"), ("latency_histogram", "overview"))
# outputs beyond which the runner draws the figures itself: each helper would be sent a copy
# of the fields it draws (about 0.4 of the outputs' 804 bytes a row, and the truth), while
# drawing takes a second or two beside a run of more than 40 minutes
HELPER_MAX_OUTPUTS = 1_000_000
# seconds a helper may take for its figures before the runner draws them itself: a fixed
# part and a part per million outputs (a 60 s run's take 0.3 s, 2000 s's about 1.5 s)
WAIT_S = 30.0
_NOT_SENT = "nothing sent"      # a group's state before its job is sent (once sent: None; failed: why)
WAIT_S_PER_MILLION = 30.0


class FigureWorkers:
    """The run's helper processes, one per group of figures (:data:`GROUPS`)."""

    def __init__(self):
        self.procs: list = ["not started"] * len(GROUPS)    # a helper each, or why there is none
        self.fallbacks: list[str] = []      # why a helper failed and its group was drawn in the runner's process
        self.planned: str | None = None     # why no helper draws, by design (one CPU, a long run)
        self._sent: list = [_NOT_SENT] * len(GROUPS)     # per group: None once sent, else why not
        self._deadline = 0.0

    def start(self) -> FigureWorkers:
        """Start the helpers (any that cannot start is left to the runner; on one CPU none
        starts: they would only take it from the runner)."""
        if host_cpus.cpus() < 2:
            self.planned = "one CPU"
            self.procs = [self.planned] * len(GROUPS)
            return self
        procs = []
        for _ in GROUPS:
            try:
                # stderr to a file: a helper that says much can never block on a full pipe
                err = tempfile.TemporaryFile()
                proc = subprocess.Popen(
                    [sys.executable, "-m", "gyrostar.hil.figure_workers"], stdin=subprocess.PIPE,
                    stdout=subprocess.PIPE, stderr=err,
                    # a Ctrl-C at the terminal is the runner's to handle: it ends the helpers
                    start_new_session=True)
                proc.err_file = err
                procs.append(proc)
            except OSError as exc:
                procs.append(f"could not start: {exc}")
        self.procs = procs
        return self

    def draw(self, folder: Path, out: np.ndarray, truth: np.ndarray | None,
             centroid_err: np.ndarray | None) -> list[Path]:
        """Draw the run's figures into ``folder`` (helpers first, the runner for any group
        a helper did not draw); the paths in :data:`RUN_FIGURES` order."""
        self.send(folder, out, truth, centroid_err)
        return self.collect(folder, out, truth, centroid_err)

    @property
    def sent(self) -> list[tuple[str, ...]]:
        """The groups of figures whose jobs are on their way to a helper."""
        return [names for names, why in zip(GROUPS, self._sent) if why is None]

    def send_outputs_only(self, folder: Path, out: np.ndarray) -> None:
        """Give the helpers whose figures need the outputs alone (no truth, no centroid
        errors) their data now, while the caller still works out the truth; :meth:`send`
        gives the others theirs."""
        self._send_groups(folder, out, None, None, outputs_only=True)

    def send(self, folder: Path, out: np.ndarray, truth: np.ndarray | None, centroid_err: np.ndarray | None) -> None:
        """Give each helper not yet sent its job (:meth:`send_outputs_only`) its figures' data
        (they draw while the caller goes on); then :meth:`collect` with the same arguments."""
        self._send_groups(folder, out, truth, centroid_err, outputs_only=False)

    def _send_groups(self, folder, out, truth, centroid_err, outputs_only: bool) -> None:
        if len(out) > HELPER_MAX_OUTPUTS and self.planned is None:
            self.close()      # a long run: the copies would cost more memory than the helpers save time
            self.planned = f"a run of {len(out)} outputs"
            self.procs = [self.planned] * len(GROUPS)
        sent = []
        for names, proc, before in zip(GROUPS, self.procs, self._sent):
            _, with_truth, with_cerr = figure_fields(names)
            if before is not _NOT_SENT or (outputs_only and (with_truth or with_cerr)):
                sent.append(before)            # sent (or failed) already, or not yet
            else:
                sent.append(self._send(proc, folder, names, out, truth, centroid_err))
        self._sent = sent
        self._deadline = time.monotonic() + WAIT_S + WAIT_S_PER_MILLION * len(out) / 1e6

    def collect(self, folder: Path, out: np.ndarray, truth: np.ndarray | None,
                centroid_err: np.ndarray | None) -> list[Path]:
        """The figures :meth:`send` gave out (any group a helper did not draw is drawn here);
        the paths in :data:`RUN_FIGURES` order."""
        paths: list[Path] = []
        for names, proc, ok in zip(GROUPS, self.procs, self._sent):
            got = self._reply(proc, self._deadline) if ok is None else ok
            if isinstance(got, list):
                paths += got
            else:
                if self.planned is None:
                    self.fallbacks.append(f"{'/'.join(names)}: {got}")
                paths += write_plots(folder, out, truth, centroid_err, names=names)
        order = {f"{n}.png": i for i, n in enumerate(RUN_FIGURES)}
        return sorted(paths, key=lambda p: order.get(p.name, len(order)))

    @staticmethod
    def _send(proc, folder, names, out, truth, centroid_err):
        """None once the job is on its way, else why not (str)."""
        if isinstance(proc, str):
            return proc
        from numpy.lib.recfunctions import repack_fields

        fields, with_truth, with_cerr = figure_fields(names)
        job = {"folder": str(folder), "names": names, "out": repack_fields(out[fields]),
               "truth": repack_fields(truth[["q", "bias"]]) if with_truth and truth is not None else None,
               "centroid_err": centroid_err if with_cerr else None}
        try:
            pickle.dump(job, proc.stdin, protocol=pickle.HIGHEST_PROTOCOL)
            proc.stdin.close()
        except (OSError, ValueError) as exc:      # it has gone (a broken pipe)
            return f"gone before its job: {exc}"
        return None

    @staticmethod
    def _reply(proc, deadline: float):
        """The helper's paths (list), or why it drew none (str)."""
        try:
            proc.wait(timeout=max(0.1, deadline - time.monotonic()))
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
            return "no answer in time"
        line = proc.stdout.read()
        proc.stdout.close()
        try:
            reply = json.loads(line.decode().strip().splitlines()[-1])
        except (ValueError, IndexError):
            return f"exit code {proc.returncode}" + (f": {_last_line(proc)}" if _last_line(proc) else "")
        if "error" in reply:
            return reply["error"]
        return [Path(p) for p in reply["paths"]]

    def close(self) -> None:
        """End any helper still running (a run stopped before its figures)."""
        for proc in self.procs:
            if isinstance(proc, str) or proc.poll() is not None:
                continue
            proc.kill()
            try:
                proc.wait(timeout=5)
            except subprocess.TimeoutExpired:
                pass
        for proc in self.procs:
            if not isinstance(proc, str):
                for f in (proc.stdin, proc.stdout, proc.err_file):
                    try:
                        f.close()
                    except OSError:       # a job's bytes the helper never read (it had gone)
                        pass


def _last_line(proc) -> str:
    """The last line a helper wrote to stderr (why it ended), or ''."""
    err = proc.err_file
    err.seek(0)
    lines = err.read().decode(errors="replace").strip().splitlines()
    return lines[-1][:300] if lines else ""


def main() -> int:
    try:
        # while the run starts up, the runner comes first (when the figures are drawn at the
        # end, nothing else of the run is busy)
        os.nice(10)
    except OSError:
        pass
    # the drawing modules are imported first: this is what the helper does while the loop runs
    from . import (
        health,  # noqa: F401  (overview)
        plots,
    )

    plots.new_figure()
    try:
        job = pickle.load(sys.stdin.buffer)
    except EOFError:         # the runner went away, or stopped before its figures
        return 0
    except Exception as exc:     # noqa: BLE001 — not a job the runner sends (someone typed at it)
        sys.stderr.write(f"gyrostar figure helper: stdin holds no figure job ({type(exc).__name__})\n")
        return 2
    try:
        paths = write_plots(Path(job["folder"]), job["out"], job["truth"], job["centroid_err"], names=job["names"])
        reply = {"paths": [str(p) for p in paths]}
    except Exception as exc:       # the runner draws them itself and says why
        reply = {"error": f"{type(exc).__name__}: {exc}"[:300]}
    sys.stdout.write(json.dumps(reply) + "\n")
    sys.stdout.flush()
    return 0


if __name__ == "__main__":
    try:
        code = main()
    except KeyboardInterrupt:
        code = 130
    os._exit(code)     # no interpreter teardown: the runner waits for this line only
