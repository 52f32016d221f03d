"""Host monotonic time → TAI and UTC.

Every loop time (``t`` of an output, gyro and exposure times) is on the host's
CLOCK_MONOTONIC (seconds since boot; never steps, may drift against UTC at NTP's slew rate,
< 500 ppm and typically < 10 ppm). At the start of a run :func:`capture` reads
CLOCK_MONOTONIC and CLOCK_REALTIME back to back (the closest of a few pairs) and keeps the
pair; with it any monotonic time maps to

* **UTC** = realtime₀ + (t − monotonic₀), as POSIX seconds (no leap seconds counted);
* **TAI** = UTC + (TAI − UTC), the leap-second count at the run's start from IERS's
  ``Leap_Second.dat`` (as shipped in astropy-iers-data) through ERFA (pyerfa, astropy's own
  time kernel: ``eraUtctai``; 37 s since 2017-01-01), expressed as
  seconds since the CCSDS epoch 1958-01-01T00:00:00 TAI (the CUC epoch of the space packets).

A leap second inside a run is not applied (the offset is taken once at the start); the
realtime clock's own accuracy (NTP/PTP discipline) bounds the absolute error, the monotonic
clock's drift against it over the run adds to that.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass

import numpy as np

CCSDS_EPOCH_JD = 2436204.5     # 1958-01-01T00:00:00 (TAI), Julian date
UNIX_EPOCH_JD = 2440587.5      # 1970-01-01T00:00:00 (UTC), Julian date


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
        """UTC ISO 8601 strings (µs, ``YYYY-MM-DDTHH:MM:SS.ffffff``) of host monotonic times
        (ERFA's ``d2dtf``: a time inside a leap second reads 23:59:60)."""
        import erfa
        import numpy as np

        u = np.atleast_1d(np.asarray(self.unix_utc(np.asarray(t_monotonic, float)), float))
        days = np.floor(u / 86400.0)
        ymdf = erfa.d2dtf("UTC", 6, UNIX_EPOCH_JD + days, (u - days * 86400.0) / 86400.0)
        return [f"{y:04d}-{mo:02d}-{d:02d}T{h:02d}:{mi:02d}:{sec:02d}.{us:06d}"
                for y, mo, d, (h, mi, sec, us) in zip(ymdf[0], ymdf[1], ymdf[2], ymdf[3])]

    def meta(self) -> dict:
        return asdict(self)


_LEAP_TABLE_LOADED = False


def _leap_seconds():
    """ERFA with the newest leap-second table at hand: IERS's ``Leap_Second.dat`` as shipped
    in ``astropy-iers-data`` (what astropy.time itself loads into ERFA) added to ERFA's
    built-in one, once per process."""
    global _LEAP_TABLE_LOADED
    import erfa

    if not _LEAP_TABLE_LOADED:
        _LEAP_TABLE_LOADED = True
        try:
            import astropy_iers_data

            raw = np.loadtxt(astropy_iers_data.IERS_LEAP_SECOND_FILE, comments="#", ndmin=2)
            table = np.zeros(len(raw), dtype=[("year", "i4"), ("month", "i4"), ("tai_utc", "f8")])
            table["year"], table["month"], table["tai_utc"] = raw[:, 3], raw[:, 2], raw[:, 4]
            erfa.leap_seconds.update(table)
        except (ImportError, OSError, ValueError):
            pass                          # ERFA's built-in table (complete up to its release)
    return erfa


def from_pair(monotonic_s: float, unix_s: float) -> TimeMap:
    """The map for one (monotonic, POSIX UTC) pair; TAI−UTC from the IERS leap-second table
    through ERFA (:func:`_leap_seconds`)."""
    erfa = _leap_seconds()
    days = float(np.floor(unix_s / 86400.0))
    utc1, utc2 = UNIX_EPOCH_JD + days, (unix_s - days * 86400.0) / 86400.0
    tai1, tai2 = erfa.utctai(utc1, utc2)
    tai_minus_utc = float(round(((tai1 - utc1) + (tai2 - utc2)) * 86400.0, 6))
    # POSIX seconds count UTC days of 86400 s: TAI since 1958 = UTC days since 1958 + TAI−UTC
    tai_s = float(unix_s) + (UNIX_EPOCH_JD - CCSDS_EPOCH_JD) * 86400.0 + tai_minus_utc
    return TimeMap(float(monotonic_s), float(unix_s), tai_minus_utc, tai_s)


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
