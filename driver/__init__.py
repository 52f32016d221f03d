"""gyrostar — software of a gyro-coupled star tracker.

Sub-packages map onto the repository folders: ``gyrostar`` is ``driver/`` (flight code
that runs on the on-board computer), ``gyrostar.mocks`` is ``mocks/`` (simulator, device
emulators, fake transports) and ``gyrostar.hil`` is ``hil/`` (flatsat runner, scenarios,
record/replay). See docs/ARCHITECTURE.md.
"""

import os as _os

__version__ = "0.1.0"

# Single-threaded BLAS: gyrostar's matrices are tiny, and a BLAS worker pool next to a
# SCHED_FIFO loop thread pinned to one CPU can livelock (the FIFO thread spins waiting for
# a worker that can never run). Set before numpy is first imported; an explicit setting wins.
_os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
