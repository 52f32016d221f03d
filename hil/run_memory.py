"""Whether a run's kept outputs, or a log read back, fit in this machine's memory, checked
before the work starts.

The runner keeps every 400 Hz output record of a run in memory for its figures (804 bytes
each, :class:`gyrostar.loop.sinks.ArraySink`: 1.16 GB per hour at 400 Hz) and, after the
loop, the simulator's truth at each one (88 bytes, written to the log as one record) and the
figures' own arrays. A run that would outgrow the memory the kernel reports available is
refused at the start with one line (exit 2), not killed by the kernel hours into it.

Reading a log back holds it in memory: a replay every record of it (the taps answer the
driver from them), an export the outputs and the truth. Measured on a 2000 s fast run's
1.56 GB log (2026-11-28): replay peaked at 5.74 GB (3.7× the log), an export's read at
2.27 GB (1.45×).
"""

from __future__ import annotations

import os

from ..errors import ConfigError
from ..loop.record import OUTPUT_DTYPE, TRUTH_DTYPE

# bytes per output: the record, the truth row and its copy for the log, the figures' arrays
BYTES_PER_OUTPUT = OUTPUT_DTYPE.itemsize + 2 * TRUTH_DTYPE.itemsize + 256
USABLE_SHARE = 0.8      # of MemAvailable: the rest stays for the log writer, the emulators and the host
REPLAY_BYTES_PER_LOG_BYTE = 3.8     # peak memory of a replay per byte of log (3.7 measured)
EXPORT_BYTES_PER_LOG_BYTE = 1.6     # of an export's read (1.45 measured)


def available_bytes(meminfo: str = "/proc/meminfo") -> int | None:
    """``MemAvailable`` (bytes) from ``meminfo``, or None where the kernel does not say."""
    try:
        with open(meminfo, encoding="ascii") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        return None
    return None


def check_kept_outputs_fit(duration_s: float, odr_hz: float, available: int | None = None,
                           meminfo: str = "/proc/meminfo") -> None:
    """Raise :class:`ConfigError` if a run of ``duration_s`` at ``odr_hz`` outputs per second
    needs more than :data:`USABLE_SHARE` of ``available`` bytes (default: ``MemAvailable`` of
    ``meminfo``; no check where it is unknown)."""
    if available is None:
        available = available_bytes(meminfo)
    if available is None or odr_hz <= 0:
        return
    need = (duration_s * odr_hz * 1.05 + 4096) * BYTES_PER_OUTPUT
    usable = USABLE_SHARE * available
    if need > usable:
        longest = max(0.0, (usable / BYTES_PER_OUTPUT - 4096) / (odr_hz * 1.05))
        raise ConfigError(
            f"a run of {duration_s:g} s keeps its {duration_s * odr_hz:.3g} outputs in memory for its figures "
            f"({need / 1e9:.1f} GB) and this machine has {available / 1e9:.1f} GB available: choose "
            f"--duration {longest:.0f} or less here (a long test with random faults: "
            f"python -m gyrostar.hil.reliability.soak, which keeps 10 outputs a second)")


def check_log_fits(path, replay: bool, available: int | None = None, meminfo: str = "/proc/meminfo") -> None:
    """Raise :class:`ConfigError` if reading the log at ``path`` back — a replay (``replay``)
    or an export — needs more than :data:`USABLE_SHARE` of ``available`` bytes (default:
    ``MemAvailable``). A path that cannot be sized is left to the reader to report."""
    try:
        size = os.path.getsize(path)
    except OSError:
        return
    if available is None:
        available = available_bytes(meminfo)
    if available is None:
        return
    need = size * (REPLAY_BYTES_PER_LOG_BYTE if replay else EXPORT_BYTES_PER_LOG_BYTE)
    if need <= USABLE_SHARE * available:
        return
    what = "replaying" if replay else "exporting"
    hint = (f"; an export (--export csv|hdf5|aem) reads only its outputs and truth, about "
            f"{size * EXPORT_BYTES_PER_LOG_BYTE / 1e9:.1f} GB" if replay else "")
    raise ConfigError(f"{what} the log {path} ({size / 1e9:.1f} GB) takes about {need / 1e9:.1f} GB of memory and "
                      f"this machine has {available / 1e9:.1f} GB available{hint}")
