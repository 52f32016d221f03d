"""Host monotonic time → TAI and UTC.

Every loop time (``t`` of an output, gyro and exposure times) is on the host's
CLOCK_MONOTONIC (seconds since boot; never steps, may drift against UTC at NTP's slew rate,
< 500 ppm and typically < 10 ppm). At the start of a run :func:`capture` reads
CLOCK_MONOTONIC and CLOCK_REALTIME back to back (the closest of a few pairs) and keeps the
pair; with it any monotonic time maps to

* **UTC** = realtime₀ + (t − monotonic₀), as POSIX seconds (no leap seconds counted);
* **TAI** = UTC + (TAI − UTC), the leap-second count at the run's start from astropy.time's
  table (37 s since 2017-01-01), expressed as seconds since the CCSDS epoch
  1958-01-01T00:00:00 TAI (the CUC epoch of the space packets).

A leap second inside a run is not applied (the offset is taken once at the start); the
realtime clock's own accuracy (NTP/PTP discipline) bounds the absolute error, the monotonic
clock's drift against it over the run adds to that.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass

CCSDS_EPOCH_ISO = "1958-01-01T00:00:00"


@dataclass(frozen=True)
class TimeMap:
    """One (monotonic, realtime) reading pair and the TAI−UTC offset valid at it (s)."""

    monotonic_s: float
    unix_s: float
    tai_minus_utc_s: float
    tai_at_monotonic0_s: float      # TAI seconds since 1958-01-01 at ``monotonic_s``

    def tai(self, t_monotonic):
        """TAI seconds since 1958-01-01 TAI of host monotonic time(s) ``t_monotonic``."""
        return self.tai_at_monotonic0_s + (t_monotonic - self.monotonic_s)

    def unix_utc(self, t_monotonic):
        """UTC as POSIX seconds of host monotonic time(s) ``t_monotonic``."""
        return self.unix_s + (t_monotonic - self.monotonic_s)

    def utc_iso(self, t_monotonic) -> list[str]:
        """UTC ISO 8601 strings (µs) of host monotonic times (astropy.time)."""
        import numpy as np
        from astropy.time import Time

        u = np.atleast_1d(self.unix_utc(np.asarray(t_monotonic, float)))
        t = Time(u, format="unix", scale="utc")
        t.precision = 6
        return list(t.isot)

    def meta(self) -> dict:
        return asdict(self)


def from_pair(monotonic_s: float, unix_s: float) -> TimeMap:
    """The map for one (monotonic, POSIX UTC) pair; TAI−UTC from astropy.time."""
    from astropy.time import Time

    utc = Time(unix_s, format="unix", scale="utc")
    tai = utc.tai
    epoch = Time(CCSDS_EPOCH_ISO, format="isot", scale="tai")
    tai_minus_utc = float(round((tai.jd1 - utc.jd1 + tai.jd2 - utc.jd2) * 86400.0, 6))
    return TimeMap(float(monotonic_s), float(unix_s), tai_minus_utc, float((tai - epoch).sec))


def capture(clock_monotonic=time.monotonic, pairs: int = 5) -> TimeMap:
    """Read the monotonic and realtime clocks back to back (tightest of ``pairs``)."""
    best = None
    for _ in range(pairs):
        a = clock_monotonic()
        u = time.time()
        b = clock_monotonic()
        if best is None or b - a < best[0]:
            best = (b - a, 0.5 * (a + b), u)
    return from_pair(best[1], best[2])


def from_meta(meta: dict | None) -> TimeMap | None:
    return TimeMap(**meta) if meta else None
