"""Run figures and a plot that need no truth: what a run on real devices can say about itself.

From the 400 Hz output records alone (plus the loop's counters and the link statistics):
mode timeline and switches, stars tracked, body rates, the bias estimate with its 3σ, the
attitude 3σ bounds from the filter covariance, the frame rate, output continuity and
link errors. ``overview.png`` shows them over time. Units are in the key names.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..loop.record import FLAG_ATTITUDE_VALID, FLAG_LINK_ERROR, MODE_NAMES, MODE_TRACK, sigma

ARCSEC = 180.0 / np.pi * 3600.0
DEG = 180.0 / np.pi


def health(out: np.ndarray, gyro_hz: float, counters: dict | None = None, link: dict | None = None) -> dict:
    """The truth-free figures of one run."""
    n = len(out)
    res: dict = {"outputs": n}
    if not n:
        return res
    dur = n / gyro_hz
    track = out["mode"] == MODE_TRACK
    valid = (out["flags"] & FLAG_ATTITUDE_VALID) != 0
    res["track_fraction"] = float(np.mean(track))
    res["mode_switches"] = int(np.count_nonzero(np.diff(out["mode"].astype(np.int16))))
    res["mode_timeline"] = _timeline(out)
    res["output_seq_gaps"] = int(np.count_nonzero(np.diff(out["seq"].astype(np.int64)) != 1))
    res["stars_tracked_median"] = float(np.median(out["n_stars"][track])) if track.any() else 0.0
    res["stars_tracked_min_in_track"] = int(out["n_stars"][track].min()) if track.any() else 0
    rate = np.linalg.norm(out["omega"], axis=1) * DEG
    res["rate_dps_max"] = float(rate.max())
    res["rate_dps_median"] = float(np.median(rate))
    sig = sigma(out["cov"])
    res["bias_estimate_dps_final"] = [float(v) for v in out["bias"][-1] * DEG]
    res["bias_3sigma_dps_final"] = [float(v) for v in 3.0 * sig[-1, 3:] * DEG]
    if np.any(track & valid):
        cross = np.sqrt(0.5 * (sig[track & valid, 0] ** 2 + sig[track & valid, 1] ** 2)) * ARCSEC
        res["attitude_3sigma_arcsec_cross_median"] = float(3.0 * np.median(cross))
        res["attitude_3sigma_arcsec_roll_median"] = float(3.0 * np.median(sig[track & valid, 2]) * ARCSEC)
    res["link_error_outputs"] = int(np.count_nonzero(out["flags"] & FLAG_LINK_ERROR))
    if counters:
        res["frames_hz"] = float(counters.get("frames", 0) / dur)
        res["frames_failed"] = int(counters.get("frames_failed", 0))
    if link:
        res["link_corrupt_frames"] = int(link.get("corrupt", 0))
        res["link_timeouts_retries"] = int(link.get("retries", 0))
        res["head_clock_steps"] = int(link.get("clock_steps", 0))
    return res


def _timeline(out: np.ndarray) -> list[list]:
    """[[start_s, end_s, mode name], ...] from the first output."""
    t = out["t"] - out["t"][0]
    cut = np.flatnonzero(np.diff(out["mode"].astype(np.int16))) + 1
    starts = np.concatenate([[0], cut])
    ends = np.concatenate([cut, [len(out)]]) - 1
    return [[round(float(t[a]), 4), round(float(t[b]), 4), MODE_NAMES[int(out["mode"][a])]]
            for a, b in zip(starts, ends)][:200]


def plot_overview(folder: Path, out: np.ndarray) -> Path | None:
    """``overview.png``: modes, stars tracked, rates, bias ± 3σ, attitude 3σ bounds."""
    if not len(out):
        return None
    from .plots import band_envelope, envelope, fixed_margins, new_figure, plain_log_labels, shade_modes

    t = out["t"] - out["t"][0]
    sig = sigma(out["cov"])
    fig, ax = new_figure(4, 1, figsize=(10, 10), sharex=True)
    for a in ax:
        shade_modes(a, t, out["mode"])
    ax[0].plot(*envelope(t, out["n_stars"].astype(np.float64)), lw=0.8)
    ax[0].set_ylabel("stars tracked")
    ax[0].set_title("run overview without truth (green: TRACK, orange: COAST)")
    for i, c in enumerate("rgb"):
        ax[1].plot(*envelope(t, out["omega"][:, i] * DEG), c, lw=0.7, label="ω" + "xyz"[i])
        b = out["bias"][:, i] * DEG * 3600
        s3 = 3.0 * sig[:, 3 + i] * DEG * 3600
        ax[2].plot(*envelope(t, b), c, lw=0.8, label="bias " + "xyz"[i])
        ax[2].fill_between(*band_envelope(t, b - s3, b + s3), color=c, alpha=0.12, lw=0, step="post")
    ax[1].set_ylabel("body rate (°/s)")
    ax[1].legend(fontsize=7, loc="upper right")
    tr = out["mode"] == MODE_TRACK
    if tr.any():                    # the prior (before the first identification) would hide the estimate
        span = np.abs(out["bias"][tr]).max() * DEG * 3600 + 3.0 * np.percentile(sig[tr, 3:], 50) * DEG * 3600
        ax[2].set_ylim(-1.5 * span, 1.5 * span)
    ax[2].set_ylabel("bias ± 3σ (°/h)")
    ax[2].legend(fontsize=7, loc="upper right")
    for i, lab in enumerate(("x", "y", "roll")):
        ax[3].semilogy(*envelope(t, 3.0 * sig[:, i] * ARCSEC), lw=0.8, label=lab)
    plain_log_labels(ax[3].yaxis)
    ax[3].set_ylabel("attitude 3σ (″)")
    ax[3].set_xlabel("time (s)")
    ax[3].legend(fontsize=7, loc="upper right")
    from ..files import whole_or_nothing

    path = folder / "overview.png"
    fixed_margins(fig, hspace=0.12)
    with whole_or_nothing(path) as part:          # a full disk leaves no 0-byte PNG
        fig.savefig(part, dpi=100, format="png")
    return path
