"""Raw FIFO frames → rates (rad/s) with per-sample times, compiled by numba.

One call converts a whole burst into preallocated arrays: no Python object per sample.
"""

from __future__ import annotations

import numpy as np
from numba import njit

FLAG_SAT_X = 0x01
FLAG_SAT_Y = 0x02
FLAG_SAT_Z = 0x04
FLAG_SATURATED = FLAG_SAT_X | FLAG_SAT_Y | FLAG_SAT_Z
FLAG_GAP = 0x08      # frames were lost just before this sample (FIFO overrun); see GyroSamples.gap_frames
FLAG_STUCK = 0x10    # this frame repeats the previous frame's raw bytes exactly (stuck output)
FLAG_TIME_EST = 0x20  # index (and so time) after a gap was estimated from the time model
FLAG_STUCK_AXIS = 0x40  # one axis's raw output has not changed for STUCK_RUN frames (stuck axis)
STUCK_RUN = 32       # frames (80 ms at 400 Hz); a live axis's noise (≥ 1.5 LSB rms) never repeats that long


@njit(cache=True)
def convert_frames(raw, n, scale, mounting, t_ref, period, k_ref, first_index, first_flags, prev_raw,
                   out_t, out_index, out_rate, out_flags, start):
    """Convert ``n`` 6-byte little-endian XYZ int16 frames in ``raw`` (uint8) into the output
    arrays from row ``start``.

    ``scale`` rad/s per LSB; ``mounting`` (3×3) rotates sensor axes into body axes; sample
    ``k`` is at host time ``t_ref + period·(k − k_ref)`` s; ``first_flags`` is OR-ed into the
    first sample; ``prev_raw`` (int32[4]: x, y, z, valid, or int32[8]: … then the per-axis
    counts of unchanged frames) carries the last frame across calls for stuck-output
    detection and is updated. With 8 entries an axis unchanged for ``STUCK_RUN`` frames
    flags ``FLAG_STUCK_AXIS``. Returns the number of samples written.
    """
    runs = prev_raw.shape[0] >= 7
    for i in range(n):
        o = start + i
        b = 6 * i
        flags = first_flags if i == 0 else 0
        sx = np.int32(raw[b] | (raw[b + 1] << 8))
        sy = np.int32(raw[b + 2] | (raw[b + 3] << 8))
        sz = np.int32(raw[b + 4] | (raw[b + 5] << 8))
        if sx >= 32768:
            sx -= 65536
        if sy >= 32768:
            sy -= 65536
        if sz >= 32768:
            sz -= 65536
        if sx == 32767 or sx == -32768:
            flags |= FLAG_SAT_X
        if sy == 32767 or sy == -32768:
            flags |= FLAG_SAT_Y
        if sz == 32767 or sz == -32768:
            flags |= FLAG_SAT_Z
        if prev_raw[3] != 0 and sx == prev_raw[0] and sy == prev_raw[1] and sz == prev_raw[2]:
            flags |= FLAG_STUCK
        if runs:
            # a saturated axis is pinned at the limit: flagged FLAG_SAT_*, not counted as stuck
            prev_raw[4] = prev_raw[4] + 1 if prev_raw[3] != 0 and sx == prev_raw[0] and not flags & FLAG_SAT_X else 0
            prev_raw[5] = prev_raw[5] + 1 if prev_raw[3] != 0 and sy == prev_raw[1] and not flags & FLAG_SAT_Y else 0
            prev_raw[6] = prev_raw[6] + 1 if prev_raw[3] != 0 and sz == prev_raw[2] and not flags & FLAG_SAT_Z else 0
            if prev_raw[4] >= STUCK_RUN or prev_raw[5] >= STUCK_RUN or prev_raw[6] >= STUCK_RUN:
                flags |= FLAG_STUCK_AXIS
        prev_raw[0] = sx
        prev_raw[1] = sy
        prev_raw[2] = sz
        prev_raw[3] = 1
        wx = sx * scale
        wy = sy * scale
        wz = sz * scale
        for r in range(3):
            out_rate[o, r] = mounting[r, 0] * wx + mounting[r, 1] * wy + mounting[r, 2] * wz
        k = first_index + i
        out_index[o] = k
        out_t[o] = t_ref + period * (k - k_ref)
        out_flags[o] = flags
    return n
