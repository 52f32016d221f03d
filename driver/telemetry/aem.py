"""CCSDS Attitude Ephemeris Message (AEM, CCSDS 504.0-B, KVN) of a run's attitude.

One data line per output with a valid attitude (``FLAG_ATTITUDE_VALID``): epoch in TAI and
the quaternion ``q`` [x, y, z, w] rotating the inertial frame (frame A) into the tracker
body = camera frame (frame B, ``SC_BODY_1``), ``ATTITUDE_DIR = A2B``, ``QUATERNION_TYPE = LAST``. A gap longer
than ``GAP_S`` (a lost attitude) starts a new segment (META/DATA block). Epochs come from
host monotonic time through the run's :class:`~gyrostar.telemetry.timescale.TimeMap`.

Frame A: the catalog is ICRS; the message says ``EME2000`` by default (what ground
software resolves without planetary ephemerides; Orekit's ``ICRF`` is barycentric and needs
them). The EME2000–ICRS frame bias is 0.02″, far below the tracker's error; pass
``ref_frame="ICRF"`` to state the ICRS exactly.
"""

from __future__ import annotations

from datetime import UTC, datetime

import numpy as np

GAP_S = 0.1
FLAG_ATTITUDE_VALID = 0x0001


def _tai_iso(timemap, t_monotonic: np.ndarray) -> list[str]:
    from astropy.time import Time, TimeDelta

    epoch = Time("1958-01-01T00:00:00", format="isot", scale="tai")
    tt = epoch + TimeDelta(np.asarray(timemap.tai(t_monotonic), float), format="sec")
    tt.precision = 6
    return list(tt.isot)


def segments(records: np.ndarray) -> list[np.ndarray]:
    """Index arrays of the contiguous stretches of valid attitude."""
    idx = np.flatnonzero(records["flags"] & FLAG_ATTITUDE_VALID)
    if not len(idx):
        return []
    cut = np.flatnonzero(np.diff(records["t"][idx]) > GAP_S) + 1
    return [s for s in np.split(idx, cut) if len(s) >= 2]


def write(path, records: np.ndarray, timemap, object_name: str = "GYROSTAR", object_id: str = "GYROSTAR-FLATSAT",
          originator: str = "GYROSTAR", ref_frame: str = "EME2000") -> dict:
    """Write the AEM; returns counts (segments, lines)."""
    segs = segments(records)
    if timemap is None:
        from ..errors import ConfigError

        raise ConfigError("this log has no time mapping (recorded before TAI/UTC were logged): no AEM epochs")
    lines = ["CCSDS_AEM_VERS = 1.0",
             f"CREATION_DATE = {datetime.now(UTC).strftime('%Y-%m-%dT%H:%M:%S')}",
             f"ORIGINATOR = {originator}", ""]
    n = 0
    for seg in segs:
        epochs = _tai_iso(timemap, records["t"][seg])
        lines += ["META_START", f"OBJECT_NAME = {object_name}", f"OBJECT_ID = {object_id}",
                  f"REF_FRAME_A = {ref_frame}", "REF_FRAME_B = SC_BODY_1", "ATTITUDE_DIR = A2B", "TIME_SYSTEM = TAI",
                  f"START_TIME = {epochs[0]}", f"STOP_TIME = {epochs[-1]}", "ATTITUDE_TYPE = QUATERNION",
                  "QUATERNION_TYPE = LAST", "META_STOP", "", "DATA_START"]
        q = records["q"][seg]
        for e, row in zip(epochs, q):
            lines.append(f"{e} {row[0]:.15e} {row[1]:.15e} {row[2]:.15e} {row[3]:.15e}")
        lines += ["DATA_STOP", ""]
        n += len(seg)
    with open(path, "w") as fh:
        fh.write("\n".join(lines))
    return {"segments": len(segs), "lines": n}
