"""Run plots (matplotlib Agg): attitude error, centroid error, bias estimate, latency."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..loop.record import MODE_COAST, MODE_TRACK
from .analysis import ARCSEC, attitude_errors

MODE_COLOURS = {MODE_TRACK: "#d8f0d8", MODE_COAST: "#f6e2c0"}
# pixel columns a run plot's traces are reduced to (a 9 in figure at 110 dpi is 990 px wide)
COLUMNS = 1200
# points a run's scatter plot draws at most (and its outliers): 100 000 draw in about 0.1 s
SCATTER_POINTS = 100_000


def envelope(x: np.ndarray, y: np.ndarray, columns: int = COLUMNS) -> tuple[np.ndarray, np.ndarray]:
    """``(x, y)`` of a line reduced to what ``columns`` pixel columns show of it: per run of
    consecutive samples, its smallest and largest value, in the order they came (x of the
    run's first and last sample). A run of only NaN stays NaN (a gap in the line); shorter
    lines come back as they are. A 60 s run's 24 000 points take a third of the drawing."""
    n = len(y)
    per = n // columns
    if per < 4:
        return x, y
    m = per * columns
    blk = y[:m].reshape(columns, per)
    with np.errstate(invalid="ignore"):
        lo = np.fmin.reduce(blk, axis=1)
        hi = np.fmax.reduce(blk, axis=1)
    first_lo = np.argmin(np.where(np.isnan(blk), np.inf, blk), axis=1) <= \
        np.argmax(np.where(np.isnan(blk), -np.inf, blk), axis=1)
    xs = x[:m].reshape(columns, per)
    ex = np.empty(2 * columns + (n - m))
    ey = np.empty_like(ex)
    ex[0:2 * columns:2], ex[1:2 * columns:2] = xs[:, 0], xs[:, -1]
    ey[0:2 * columns:2] = np.where(first_lo, lo, hi)
    ey[1:2 * columns:2] = np.where(first_lo, hi, lo)
    ex[2 * columns:], ey[2 * columns:] = x[m:], y[m:]
    return ex, ey


def scatter_sample(err: np.ndarray, rms: float, most: int = SCATTER_POINTS) -> tuple[np.ndarray, int]:
    """``(rows to draw, k)`` of a scatter of ``err`` (n, d): every ``k``-th row, and every row
    with a value beyond 3 × ``rms`` — all rows (k = 1) when there are no more than ``most``."""
    n = len(err)
    if n <= most:
        return np.arange(n), 1
    every = -(-n // most)
    keep = np.zeros(n, bool)
    keep[::every] = True
    keep |= (np.abs(err) > 3.0 * rms).any(axis=1)
    return np.flatnonzero(keep), every


def band_envelope(x: np.ndarray, lo: np.ndarray, hi: np.ndarray,
                  columns: int = COLUMNS) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(x, lo, hi)`` of a shaded band reduced to ``columns`` pixel columns, to draw as steps
    (``fill_between(..., step="post")``): per run of consecutive samples the lowest ``lo``
    and highest ``hi``, held from the run's first sample to the next run's, so the band drawn
    covers every sample's. Shorter bands come back as they are."""
    n = len(x)
    per = n // columns
    if per < 4:
        return x, lo, hi
    m = per * columns
    with np.errstate(invalid="ignore"):
        blo = np.fmin.reduce(lo[:m].reshape(columns, per), axis=1)
        bhi = np.fmax.reduce(hi[:m].reshape(columns, per), axis=1)
    # the last whole run is held to its last sample, then the samples after it as they are
    return np.r_[x[:m:per], x[m - 1], x[m:]], np.r_[blo, blo[-1], lo[m:]], np.r_[bhi, bhi[-1], hi[m:]]


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


def new_figure(nrows: int = 1, ncols: int = 1, **kw):
    """``(figure, axes)`` drawn by Agg, outside pyplot: no figure manager to close, and a
    tenth of a second less to import (``matplotlib.figure`` without ``pyplot``'s backend
    machinery). ``kw``: ``figsize`` and the rest go to the figure, ``sharex``/``sharey`` to
    its subplots."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    share = {k: kw.pop(k) for k in ("sharex", "sharey") if k in kw}
    fig = Figure(**kw)
    FigureCanvasAgg(fig)
    return fig, fig.subplots(nrows, ncols, **share)


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


RUN_FIGURES = ("attitude_error", "bias_estimate", "centroid_error", "latency_histogram", "overview")


def write_plots(folder: Path, out: np.ndarray, truth: np.ndarray | None,
                centroid_err: np.ndarray | None = None, names: tuple = RUN_FIGURES) -> list[Path]:
    """Write the PNGs ``names`` (of :data:`RUN_FIGURES`, in that order) of one run into
    ``folder``; returns the paths of those it drew (one needing truth or centroid errors is
    left out without them).

    ``out``: the run's outputs (fields t, mode, q, bias, omega, cov, n_stars, latency_us);
    ``truth`` (optional): the truth at each output (q, bias); ``centroid_err`` (optional): an
    (n, 3) array of [t, error_col_px, error_row_px] of tracked stars' predicted centroids
    against the truth.
    """
    unknown = set(names) - set(RUN_FIGURES)
    if unknown:
        raise ValueError(f"no run figure {sorted(unknown)}: the figures are {', '.join(RUN_FIGURES)}")
    paths = []
    for name in RUN_FIGURES:
        if name in names:
            path = _figure(name)(folder, out, truth, centroid_err)
            if path is not None:
                paths.append(path)
    return paths


def _figure(name: str):
    """The function that draws run figure ``name``: ``f(folder, out, truth, centroid_err)``."""
    if name == "overview":
        from .health import plot_overview

        return lambda folder, out, truth, cerr: plot_overview(folder, out)
    return {"attitude_error": _attitude_error, "bias_estimate": _bias_estimate, "centroid_error": _centroid_error,
            "latency_histogram": _latency_histogram}[name]


def figure_fields(names) -> tuple[list[str], bool, bool]:
    """``(output fields, truth needed, centroid errors needed)`` to draw ``names``: what a
    figure worker is sent of a run."""
    fields = {"t", "mode"}
    for name in names:
        fields |= set(_FIGURE_FIELDS[name])
    return sorted(fields), bool({"attitude_error", "bias_estimate"} & set(names)), "centroid_error" in names


_FIGURE_FIELDS = {"attitude_error": ("q",), "bias_estimate": ("bias",), "centroid_error": (),
                  "latency_histogram": ("latency_us",), "overview": ("n_stars", "omega", "bias", "cov")}


def _rel_t(out: np.ndarray) -> np.ndarray:
    return out["t"] - (out["t"][0] if len(out) else 0.0)


def _symmetric_limit(err: np.ndarray, least: float) -> float:
    """± limit of an error panel: 3× the 99th percentile of |err|, at least ``least``."""
    return max(float(np.percentile(np.abs(err), 99)) * 3 if err.size else least, least)


def _clip_note(err: np.ndarray, lim: float) -> str:
    """Legend note for points beyond ±lim ('' when none is)."""
    n = int(np.count_nonzero(np.abs(err) > lim))
    return f" ({n} beyond ±{lim:.3g}, max {np.abs(err).max():.3g})" if n else ""


def _attitude_error(folder: Path, out, truth, cerr) -> Path | None:
    if truth is None or len(truth) != len(out):
        return None
    t = _rel_t(out)
    err = attitude_errors(out, truth) * ARCSEC
    # roll about the boresight is ~f/r_star worse than the cross-boresight axes: its own panel and scale
    fig, (ax, ax_roll) = new_figure(2, 1, figsize=(9, 6), sharex=True)
    lim = _symmetric_limit(err[:, :2], 5.0)
    for a in (ax, ax_roll):
        shade_modes(a, t, out["mode"])
    for i, lab in enumerate(("x (cross-boresight)", "y (cross-boresight)")):
        ax.plot(*envelope(t, err[:, i]), lw=0.7, label=lab + _clip_note(err[:, i], lim))
    ax.set_ylim(-lim, lim)
    ax.set_ylabel("cross-boresight (arcsec)")
    ax.set_title("attitude error vs truth (green: TRACK, orange: COAST)")
    ax.legend(loc="upper right", fontsize=8)
    lim_r = _symmetric_limit(err[:, 2], 5.0)
    ax_roll.plot(*envelope(t, err[:, 2]), lw=0.7, color="C2", label="roll (about the boresight)"
                 + _clip_note(err[:, 2], lim_r))
    ax_roll.set_ylim(-lim_r, lim_r)
    ax_roll.set_xlabel("time (s)")
    ax_roll.set_ylabel("roll (arcsec)")
    ax_roll.legend(loc="upper right", fontsize=8)
    return _save(fig, folder / "attitude_error.png", hspace=0.15)


def _bias_estimate(folder: Path, out, truth, cerr) -> Path | None:
    if truth is None or len(truth) != len(out):
        return None
    t = _rel_t(out)
    fig, ax = new_figure(figsize=(9, 4))
    shade_modes(ax, t, out["mode"])
    deg_h = 180 / np.pi * 3600
    for i, c in enumerate("rgb"):
        ax.plot(*envelope(t, out["bias"][:, i] * deg_h), c, lw=0.8, label=f"estimate {'xyz'[i]}")
        ax.plot(*envelope(t, truth["bias"][:, i] * deg_h), c + "--", lw=0.8, label=f"truth {'xyz'[i]}")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("gyro bias (deg/h)")
    ax.set_title("gyro bias estimate")
    ax.legend(loc="upper right", fontsize=7, ncol=2)
    return _save(fig, folder / "bias_estimate.png")


def _centroid_error(folder: Path, out, truth, centroid_err) -> Path | None:
    if centroid_err is None or not len(centroid_err):
        return None
    fig, ax = new_figure(figsize=(9, 4))
    rms = np.sqrt(np.mean(centroid_err[:, 1:] ** 2))
    shown, every = scatter_sample(centroid_err[:, 1:], rms)
    ct = centroid_err[shown, 0] - (out["t"][0] if len(out) else 0)
    lim = _symmetric_limit(centroid_err[:, 1:], 0.05)          # px: the errors' own scale, not ±1 px
    ax.plot(ct, centroid_err[shown, 1], ".", ms=1, label="column" + _clip_note(centroid_err[:, 1], lim))
    ax.plot(ct, centroid_err[shown, 2], ".", ms=1, label="row" + _clip_note(centroid_err[:, 2], lim))
    ax.set_ylim(-lim, lim)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("centroid error (px)")
    note = f"; every {every}th of {len(centroid_err)} shown, and all beyond 3×RMS" if every > 1 else ""
    ax.set_title(f"tracked stars' centroid error vs truth (RMS {rms:.3f} px per axis{note})", fontsize=10)
    ax.legend(loc="upper right", fontsize=8)
    return _save(fig, folder / "centroid_error.png")


def _latency_histogram(folder: Path, out, truth, cerr) -> Path | None:
    lat = out["latency_us"][np.isfinite(out["latency_us"])]
    if not len(lat):
        return None
    fig, ax = new_figure(figsize=(6, 4))
    ax.hist(lat, bins=100, log=True, histtype="stepfilled")     # one polygon, not 100 bars
    plain_log_labels(ax.yaxis)
    p99 = np.percentile(lat, 99)
    ax.axvline(p99, color="r", lw=0.8, label=f"p99 {p99:.0f} µs")
    # latency_us: host time from the FIFO read to the output (TELEMETRY.md); in a --fast run the
    # simulated clock stands still meanwhile, so it is the host's compute time alone
    ax.set_xlabel("host time, gyro FIFO read → output (µs)")
    ax.set_ylabel("outputs")
    ax.set_title("loop latency (host time; in a --fast run the compute time alone)", fontsize=10)
    ax.legend()
    return _save(fig, folder / "latency_histogram.png")


def _save(fig, path: Path, hspace: float | None = None) -> Path:
    """``fig`` as the PNG ``path``, whole or not at all (a full disk leaves no 0-byte PNG)."""
    from ..files import whole_or_nothing

    fixed_margins(fig, hspace=hspace)
    with whole_or_nothing(path) as part:
        fig.savefig(part, dpi=110, format="png")
    return path
