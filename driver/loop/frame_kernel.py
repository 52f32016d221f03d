"""One compiled call per measured frame of the image stage (no per-star Python).

:func:`apply_frame` takes a streamed or captured frame's measured windows to the filter and
the tracks: the stars the filter may take (:func:`gyrostar.loop.image_kernels.
select_measured`), which of them agree with each other (:func:`gyrostar.starid.verify.
consistent`), the delayed update at mid-exposure on those
(:func:`gyrostar.loop.update_kernel.update_at_mid`) and the gate's verdict on each track
(:func:`gyrostar.loop.image_kernels.score_slots`) — the same steps, in the same order, as
separate calls would take, in one.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..starid.verify import consistent
from .image_kernels import score_slots, select_measured
from .update_kernel import update_at_mid

N_MEASURED, N_CONSISTENT, N_USED, N_ACCEPTED = 0, 1, 2, 3    # apply_frame's counts


@njit(cache=True)
def apply_frame(wins, nav_planned, state, b_mid, sig, active, nav, misses, rejects, refs, cam_var, coast, k_sigma,
                tol_min, q, b, P, ts, hist_t, hist_q, ih, prm, kappa, mid, smoothed, t_mid, min_used, gate, qd_margin,
                gap_s, wrong_id_rejects):
    """Apply one frame's measured windows.

    Windows (``wins``, ``nav_planned``, ``state``, ``b_mid`` (n, 3) body unit vectors at
    mid-exposure ``t_mid`` (s), ``sig`` (n,) rad) and the tracks' arrays (``active``,
    ``nav``, ``misses``, ``rejects`` in place, catalog vectors ``refs`` (S, 3)) as
    :func:`select_measured` and :func:`score_slots` take them; ``cam_var`` (rad²), ``coast``
    as there. ``k_sigma``, ``tol_min`` (rad): :func:`consistent`'s tolerance. The filter's
    arrays ``q`` … ``smoothed`` (in place), ``min_used``, ``gate``, ``qd_margin``, ``gap_s`` as
    :func:`update_at_mid` takes them; only the consistent stars go to it.

    Returns ``(counts (4,) int64, info, wrong)``: counts [measured stars, consistent ones,
    stars the update used (0: not applied), stars its gates accepted]; ``info`` the sum of
    1/σ² (rad⁻²) over the accepted stars; ``wrong`` the slots that have now failed the gate
    ``wrong_id_rejects`` times in a row.
    """
    slots, bu, ru, su = select_measured(wins, nav_planned, state, b_mid, sig, active, nav, misses, refs, cam_var,
                                        coast)
    k = slots.shape[0]
    counts = np.zeros(4, np.int64)
    info = 0.0
    if k == 0:
        return counts, info, np.empty(0, np.int64)
    acc = np.zeros(k, np.uint8)
    idx = np.flatnonzero(consistent(bu, ru, su, k_sigma, tol_min))
    n_ok = idx.shape[0]
    used = 0
    if n_ok == k:
        used = update_at_mid(q, b, P, ts, hist_t, hist_q, ih, prm, kappa, mid, smoothed, t_mid, bu, ru, su, acc,
                             min_used, gate, qd_margin, gap_s)
    elif n_ok:
        sub = np.zeros(n_ok, np.uint8)
        used = update_at_mid(q, b, P, ts, hist_t, hist_q, ih, prm, kappa, mid, smoothed, t_mid, bu[idx], ru[idx],
                             su[idx], sub, min_used, gate, qd_margin, gap_s)
        acc[idx] = sub
    good = acc != 0
    for i in range(k):
        if good[i]:
            info += 1.0 / (su[i] * su[i])
    wrong = score_slots(slots, good, misses, rejects, wrong_id_rejects)
    counts[N_MEASURED] = k
    counts[N_CONSISTENT] = n_ok
    counts[N_USED] = used
    counts[N_ACCEPTED] = np.count_nonzero(good)
    return counts, info, wrong
