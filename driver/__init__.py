"""gyrostar — software of a gyro-coupled star tracker.

Sub-packages map onto the repository folders: ``gyrostar`` is ``driver/`` (flight code
that runs on the on-board computer), ``gyrostar.mocks`` is ``mocks/`` (simulator, device
emulators, fake transports) and ``gyrostar.hil`` is ``hil/`` (flatsat runner, scenarios,
record/replay). See docs/ARCHITECTURE.md.
"""

__version__ = "0.1.0"
