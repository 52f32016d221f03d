"""Run plots (matplotlib Agg): attitude error, centroid error, bias estimate, latency."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..loop.record import MODE_COAST, MODE_TRACK
from .analysis import ARCSEC, attitude_errors

MODE_COLOURS = {MODE_TRACK: "#d8f0d8", MODE_COAST: "#f6e2c0"}


def shade_modes(ax, t, mode):
    """Shade TRACK (green) and COAST (orange) stretches; ACQUIRE is left white."""
    if not len(t):
        return
    edges = np.flatnonzero(np.diff(mode.astype(int))) + 1
    starts = np.r_[0, edges]
    stops = np.r_[edges, len(t) - 1]
    for a, b in zip(starts, stops):
        colour = MODE_COLOURS.get(int(mode[a]))
        if colour:
            ax.axvspan(t[a], t[b], color=colour, lw=0, zorder=0)


def plain_log_labels(axis) -> None:
    """Label a log axis 10, 100, 1000 … (``%g``) instead of mathtext powers of ten, whose
    first use builds the mathtext parser (about 0.1 s of a run's plotting)."""
    from matplotlib.ticker import FormatStrFormatter, NullFormatter

    axis.set_major_formatter(FormatStrFormatter("%g"))
    axis.set_minor_formatter(NullFormatter())


def fixed_margins(fig, left_in: float = 0.85, right_in: float = 0.2, bottom_in: float = 0.55,
                  top_in: float = 0.4, hspace: float | None = None) -> None:
    """Margins in inches around the axes (room for tick labels, axis labels and a title),
    set once instead of ``tight_layout``, which measures every tick label by drawing the
    figure an extra time (a run's plots take about a third less time)."""
    w, h = fig.get_size_inches()
    fig.subplots_adjust(left=left_in / w, right=1.0 - right_in / w, bottom=bottom_in / h, top=1.0 - top_in / h,
                        hspace=hspace)


def write_plots(folder: Path, out: np.ndarray, truth: np.ndarray | None,
                centroid_err: np.ndarray | None = None) -> list[Path]:
    """Write the PNGs of one run into ``folder``; returns their paths.

    ``centroid_err`` (optional) is an (n, 3) array of [t, error_col_px, error_row_px] of
    tracked stars' predicted centroids against the truth.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    paths = []
    t = out["t"] - (out["t"][0] if len(out) else 0.0)
    if truth is not None and len(truth) == len(out):
        err = attitude_errors(out, truth) * ARCSEC
        fig, ax = plt.subplots(figsize=(9, 4))
        shade_modes(ax, t, out["mode"])
        for i, lab in enumerate(("x (cross-boresight)", "y (cross-boresight)", "roll")):
            ax.plot(t, err[:, i], lw=0.7, label=lab)
        lim = np.percentile(np.abs(err[:, :2]), 99) * 3 if len(err) else 10
        ax.set_ylim(-max(lim, 5), max(lim, 5))
        ax.set_xlabel("time (s)")
        ax.set_ylabel("attitude error (arcsec)")
        ax.set_title("attitude error vs truth (green: TRACK, orange: COAST)")
        ax.legend(loc="upper right", fontsize=8)
        paths.append(_save(fig, folder / "attitude_error.png"))

        fig, ax = plt.subplots(figsize=(9, 4))
        shade_modes(ax, t, out["mode"])
        deg_h = 180 / np.pi * 3600
        for i, c in enumerate("rgb"):
            ax.plot(t, out["bias"][:, i] * deg_h, c, lw=0.8, label=f"estimate {'xyz'[i]}")
            ax.plot(t, truth["bias"][:, i] * deg_h, c + "--", lw=0.8, label=f"truth {'xyz'[i]}")
        ax.set_xlabel("time (s)")
        ax.set_ylabel("gyro bias (deg/h)")
        ax.set_title("gyro bias estimate")
        ax.legend(loc="upper right", fontsize=7, ncol=2)
        paths.append(_save(fig, folder / "bias_estimate.png"))
    if centroid_err is not None and len(centroid_err):
        fig, ax = plt.subplots(figsize=(9, 4))
        ax.plot(centroid_err[:, 0] - (out["t"][0] if len(out) else 0), centroid_err[:, 1], ".", ms=1, label="column")
        ax.plot(centroid_err[:, 0] - (out["t"][0] if len(out) else 0), centroid_err[:, 2], ".", ms=1, label="row")
        ax.set_ylim(-1, 1)
        ax.set_xlabel("time (s)")
        ax.set_ylabel("centroid error (px)")
        rms = np.sqrt(np.mean(centroid_err[:, 1:] ** 2))
        ax.set_title(f"tracked stars' centroid error vs truth (RMS {rms:.3f} px per axis)")
        ax.legend(loc="upper right", fontsize=8)
        paths.append(_save(fig, folder / "centroid_error.png"))
    lat = out["latency_us"][np.isfinite(out["latency_us"])]
    if len(lat):
        fig, ax = plt.subplots(figsize=(6, 4))
        ax.hist(lat, bins=100, log=True)
        plain_log_labels(ax.yaxis)
        p99 = np.percentile(lat, 99)
        ax.axvline(p99, color="r", lw=0.8, label=f"p99 {p99:.0f} µs")
        ax.set_xlabel("gyro sample → output latency (µs)")
        ax.set_ylabel("outputs")
        ax.set_title("loop latency")
        ax.legend()
        paths.append(_save(fig, folder / "latency_histogram.png"))
    return paths


def _save(fig, path: Path) -> Path:
    fixed_margins(fig)
    fig.savefig(path, dpi=110)
    import matplotlib.pyplot as plt

    plt.close(fig)
    return path
