"""Local Dask clusters that stay quiet: worker logs at CRITICAL (a failed task reaches the
client as its exception, which the CLI prints as one line) and Ctrl-C left to the client
process (a terminal's SIGINT reaches the whole process group; each worker ignores it, the
client stops the work and closes the cluster)."""

from __future__ import annotations

import logging

LOGGERS = ("distributed", "distributed.scheduler", "distributed.nanny", "distributed.core", "distributed.worker",
           "distributed.http.proxy", "distributed.comm")


def silence_logs() -> None:
    """Dask's loggers in this process to CRITICAL."""
    for name in LOGGERS:
        logging.getLogger(name).setLevel(logging.CRITICAL)


def ignore_sigint() -> None:
    """SIGINT ignored in this process (from its main thread only: signals cannot be set elsewhere)."""
    import signal
    import threading

    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.SIG_IGN)


def quiet_worker_plugin():
    """A ``WorkerPlugin`` that makes each worker ignore SIGINT when it starts."""
    from distributed.diagnostics.plugin import WorkerPlugin

    class Quiet(WorkerPlugin):
        idempotent = True
        name = "gyrostar-quiet-worker"

        def setup(self, worker=None):
            ignore_sigint()

    return Quiet()
