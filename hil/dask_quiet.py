"""Local Dask clusters that stay quiet: worker logs at CRITICAL (a failed task reaches the
client as its exception, which the CLI prints as one line) and Ctrl-C left to the client
process (a terminal's SIGINT reaches the whole process group; each worker ignores it, the
client stops the work and closes the cluster)."""

from __future__ import annotations

import logging

LOGGERS = ("distributed", "distributed.scheduler", "distributed.nanny", "distributed.core", "distributed.worker",
           "distributed.http.proxy", "distributed.comm")


class ClosedCommFilter(logging.Filter):
    """Drops asyncio's "exception was never retrieved" records of a Dask connection that closed
    (``CommClosedError``, ``StreamClosedError``): what a cluster shut down by Ctrl-C or SIGTERM
    leaves behind, a traceback per closed stream, not an error of the command."""

    CLOSED = ("CommClosedError", "StreamClosedError")

    def filter(self, record: logging.LogRecord) -> bool:
        exc = record.exc_info[1] if record.exc_info else None
        while exc is not None:
            if type(exc).__name__ in self.CLOSED:
                return False
            exc = exc.__cause__ or exc.__context__
        return True


_CLOSED_FILTER = ClosedCommFilter()


def silence_logs() -> None:
    """Dask's loggers in this process to CRITICAL, and asyncio's reports of its closed
    connections dropped (:class:`ClosedCommFilter`)."""
    for name in LOGGERS:
        logging.getLogger(name).setLevel(logging.CRITICAL)
    asyncio_log = logging.getLogger("asyncio")
    if _CLOSED_FILTER not in asyncio_log.filters:
        asyncio_log.addFilter(_CLOSED_FILTER)


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


def distributed():
    """``dask.distributed`` (the module), or :class:`~gyrostar.errors.NotAvailableError`."""
    try:
        import dask.distributed as dd
    except ImportError as exc:
        from ..errors import NotAvailableError

        raise NotAvailableError(f"dask.distributed is needed for the Monte Carlo: {exc}") from exc
    return dd


def local_client(workers: int, dashboard_address: str | None = None):
    """``(cluster, client)``: a quiet ``LocalCluster`` of ``workers`` one-thread processes
    (:class:`~gyrostar.errors.ConfigError` for fewer than one)."""
    from ..errors import ConfigError

    if workers < 1:
        raise ConfigError(f"--workers must be ≥ 1, got {workers}")
    dd = distributed()
    silence_logs()
    cluster = dd.LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                              dashboard_address=dashboard_address, silence_logs=logging.CRITICAL)
    return cluster, dd.Client(cluster)
