"""The loop's output record: one per gyro sample (400 Hz), a numpy structured dtype.

Every field is little-endian and fixed-size, so the raw bytes of an array of records are
the UDP datagram payload and the log's OUTPUT payload (see docs/FLATSAT.md).

=================  ==========  ===============================================================
field              type        meaning (frames: gyrostar.attitude; body = camera frame)
=================  ==========  ===============================================================
``t``              f8          host time of the gyro sample, s (monotonic or simulated clock)
``seq``            u4          output counter (gaps mean lost outputs)
``mode``           u1          MODE_ACQUIRE 0, MODE_TRACK 1, MODE_COAST 2
``n_stars``        u1          stars tracked; in COAST the stars the newest image still measured (0 in
                               a star-less COAST). The tracked stars' rows of ``star_id``/``centroid_px``
                               are those with ``star_id`` ≥ 0 (in COAST more than ``n_stars``)
``flags``          u2          quality flags, ``FLAG_*`` below; bits 12–15: the reason code ``REASON_*``
``q``              f8[4]       attitude estimate [x, y, z, w], ICRS → body
``omega``          f8[3]       body rate, bias-corrected, rad/s
``bias``           f8[3]       gyro bias estimate, rad/s
``cov``            f8[6,6]     covariance of [δθ (rad, body), bias (rad/s)]
``star_id``        i4[16]      catalog ids of tracked stars (-1 = none)
``centroid_px``    f4[16,2]    predicted centroids (column, row) in pixels, sensor coords
``latency_us``     f4          host time from the gyro sample's FIFO read to this output, µs
``t_mid``          f8          mid-exposure host time of the newest frame applied, s (nan: none)
``q_mid``          f8[4]       attitude at ``t_mid`` (filtered with that frame), ICRS → body
``cov_mid``        f8[3,3]     covariance of ``q_mid``'s δθ (rad², body axes at ``t_mid``)
``t_mid_s``        f8          mid-exposure time of the frame before (s; nan: none)
``q_mid_s``        f8[4]       attitude at ``t_mid_s`` smoothed with the newest frame
``cov_mid_s``      f8[3,3]     its covariance (rad², body axes at ``t_mid_s``)
=================  ==========  ===============================================================

Two attitude products: the real-time one (``q``, ``cov``) at every gyro sample, and per
frame the attitude at mid-exposure with its own timestamp (``t_mid``, ``q_mid``,
``cov_mid``, filtered with that frame; ``*_mid_s``: the frame before, smoothed with the
next), as conventional star trackers report; they repeat on every record until the next
frame is applied.
"""

from __future__ import annotations

import numpy as np

MAX_STARS = 16

MODE_ACQUIRE = 0
MODE_TRACK = 1
MODE_COAST = 2
MODE_NAMES = {MODE_ACQUIRE: "ACQUIRE", MODE_TRACK: "TRACK", MODE_COAST: "COAST"}

FLAG_ATTITUDE_VALID = 0x0001   # q is from an identified attitude (TRACK or COAST after TRACK)
FLAG_IMAGE_UPDATE = 0x0002     # an image update was applied at this sample
FLAG_GYRO_GAP = 0x0004         # samples before this one were lost (FIFO overrun, bus error)
FLAG_GYRO_SATURATED = 0x0008   # an axis hit the gyro's range
FLAG_FEW_STARS = 0x0010        # fewer than 2 valid stars in the last image
FLAG_LINK_ERROR = 0x0020       # the last image failed (timeout, corrupt frame, head error)
FLAG_HEAD_LOST = 0x0040        # the head does not answer (disconnected); reconnecting
FLAG_OVERRUN = 0x0080          # the loop missed its deadline before this sample
FLAG_BIAS_CONVERGED = 0x0100   # bias covariance below threshold
FLAG_ID_VERIFIED = 0x0200      # identification verified by residuals after the last solve
FLAG_GYRO_STUCK = 0x0400       # a gyro axis output is stuck (unchanged for ≥ 32 frames: gyro.convert.FLAG_STUCK_AXIS)
FLAG_UPDATE_APPLIED = 0x0800   # the first output after an image update (the one before it: the last prior)
# Bits 12–15 of ``flags``: why the output is not a tracked, image-updated attitude (0: it is).
# Read it with :func:`reason`; FLAG_ATTITUDE_VALID says whether ``q`` may be used at all
# (with ``cov``: a coasted attitude is valid, its covariance growing with the gyro's noise).
REASON_SHIFT = 12
REASON_MASK = 0xF000
REASON_NONE = 0           # tracking: the last image updated the attitude
REASON_ACQUIRING = 1      # no attitude yet (lost in space, or confirming a new identification)
REASON_FEW_STARS = 2      # coasting on the gyro: the last images held too few usable stars
REASON_BLINDED = 3        # coasting or waiting: the image background is near full scale (Sun, Earth, Moon)
REASON_RATE = 4           # coasting: the body turns faster than the spots can be measured
REASON_HEAD_LOST = 5      # coasting: the head does not answer
REASON_NAMES = {REASON_NONE: "none", REASON_ACQUIRING: "acquiring", REASON_FEW_STARS: "few_stars",
                REASON_BLINDED: "blinded", REASON_RATE: "rate", REASON_HEAD_LOST: "head_lost"}
FLAG_NAMES = {
    FLAG_ATTITUDE_VALID: "attitude_valid", FLAG_IMAGE_UPDATE: "image_update",
    FLAG_GYRO_GAP: "gyro_gap", FLAG_GYRO_SATURATED: "gyro_saturated",
    FLAG_FEW_STARS: "few_stars", FLAG_LINK_ERROR: "link_error", FLAG_HEAD_LOST: "head_lost",
    FLAG_OVERRUN: "overrun", FLAG_BIAS_CONVERGED: "bias_converged", FLAG_ID_VERIFIED: "id_verified",
    FLAG_GYRO_STUCK: "gyro_stuck", FLAG_UPDATE_APPLIED: "update_applied",
}

OUTPUT_DTYPE = np.dtype([
    ("t", "<f8"), ("seq", "<u4"), ("mode", "u1"), ("n_stars", "u1"), ("flags", "<u2"),
    ("q", "<f8", (4,)), ("omega", "<f8", (3,)), ("bias", "<f8", (3,)), ("cov", "<f8", (6, 6)),
    ("star_id", "<i4", (MAX_STARS,)), ("centroid_px", "<f4", (MAX_STARS, 2)), ("latency_us", "<f4"),
    ("t_mid", "<f8"), ("q_mid", "<f8", (4,)), ("cov_mid", "<f8", (3, 3)),
    ("t_mid_s", "<f8"), ("q_mid_s", "<f8", (4,)), ("cov_mid_s", "<f8", (3, 3)),
])
MID_N = 14
"""Length of the mid-exposure product array the loop keeps: [t_mid, q_mid (4), cov_mid (9)]."""

TRUTH_DTYPE = np.dtype([
    ("t", "<f8"), ("q", "<f8", (4,)), ("omega", "<f8", (3,)), ("bias", "<f8", (3,)),
])
"""Simulator truth at each gyro sample (simulated flatsats only): attitude, rate, bias."""

UDP_MAGIC = b"GYS1"
"""UDP datagram = UDP_MAGIC + u16 record size + u16 count + count raw OUTPUT_DTYPE records."""


def empty(n: int = 0) -> np.ndarray:
    """An array of ``n`` zeroed output records with ids set to -1."""
    out = np.zeros(n, OUTPUT_DTYPE)
    out["star_id"] = -1
    out["t_mid"] = np.nan
    out["t_mid_s"] = np.nan
    return out


def sigma(cov: np.ndarray) -> np.ndarray:
    """1σ per axis (square roots of the diagonal, negatives clipped to 0) of covariances
    (…, n, n): a record's ``cov`` (rad, rad/s) or ``cov_mid`` (rad)."""
    return np.sqrt(np.maximum(np.diagonal(cov, axis1=-2, axis2=-1), 0.0))


def flag_names(flags: int) -> list[str]:
    return [name for bit, name in FLAG_NAMES.items() if flags & bit]


def reason(flags):
    """The reason code(s) ``REASON_*`` of output flags (an int or an array)."""
    return (flags & REASON_MASK) >> REASON_SHIFT


def describe() -> dict:
    """JSON-safe description of the record layout (stored in every log's META)."""
    return {"dtype": OUTPUT_DTYPE.descr, "itemsize": OUTPUT_DTYPE.itemsize, "modes": MODE_NAMES,
            "flags": {name: bit for bit, name in FLAG_NAMES.items()},
            "reason_shift": REASON_SHIFT, "reasons": REASON_NAMES,
            "truth_dtype": TRUTH_DTYPE.descr}
