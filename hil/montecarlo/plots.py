"""Campaign plots (matplotlib Agg), each titled with its run count and carrying error bars.

* ``error_cdf.png`` — pooled CDF of the cross-boresight error in TRACK, with the 90 % band
  of a bootstrap over runs;
* ``error_vs_rate.png`` — 1σ per axis by body-rate bin, 90 % bootstrap interval over runs;
* ``ttff_hist.png`` — time to first fix, counts with Poisson (√n) error bars.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

from .metrics import ERR_EDGES_ARCSEC, RATE_BINS

N_BOOT = 200


def cdf_span(hist: np.ndarray) -> tuple[float, float]:
    """``(lo, hi)`` arcsec of the error CDF's axis: from half the 0.1th percentile's bin edge to
    twice the largest error's bin edge (the histogram spans 10⁻² … 10⁵″ whatever the errors)."""
    c = np.cumsum(hist)
    if not c.size or c[-1] <= 0:
        return float(ERR_EDGES_ARCSEC[1]), float(ERR_EDGES_ARCSEC[-1])
    first = int(np.searchsorted(c, 1e-3 * c[-1]))                  # bin of the 0.1th percentile
    last = int(np.flatnonzero(hist)[-1])
    lo = max(float(ERR_EDGES_ARCSEC[max(first, 1)]) / 2.0, float(ERR_EDGES_ARCSEC[1]))
    return lo, min(float(ERR_EDGES_ARCSEC[last + 1]) * 2.0, float(ERR_EDGES_ARCSEC[-1]))


def write_plots(rows: list[dict], folder: Path, seed: int = 0) -> list[Path]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ok = [r for r in rows if not r["failed"]]
    folder.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed)
    out: list[Path] = []
    n = len(ok)
    if not n:
        return out
    hists = np.array([r["err_hist"] for r in ok], float)
    boot = rng.integers(0, n, size=(N_BOOT, n))

    def cdf(h):
        c = np.cumsum(h, axis=-1)
        return c / np.maximum(c[..., -1:], 1)

    x = ERR_EDGES_ARCSEC[1:]
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    band = np.array([cdf(hists[b].sum(0)) for b in boot])
    lo, hi = np.percentile(band, [5, 95], axis=0)
    ax.fill_between(x, lo, hi, alpha=0.3, step="post", label="90 % bootstrap band")
    ax.step(x, cdf(hists.sum(0)), where="post", label="pooled")
    ax.set_xscale("log")
    ax.set_xlim(*cdf_span(hists.sum(0)))          # the errors' own span, not the histogram's 1e-2 … 1e5″
    ax.set_xlabel("cross-boresight attitude error in TRACK (arcsec)")
    ax.set_ylabel("fraction of outputs")
    ax.set_title(f"attitude error CDF, {n} runs")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    out.append(_save(fig, folder / "error_cdf.png"))

    sq = np.array([r["rate_sq"] for r in ok], float)
    cnt = np.array([r["rate_n"] for r in ok], float)
    with np.errstate(invalid="ignore", divide="ignore"):
        est = np.sqrt(sq.sum(0) / cnt.sum(0))
        bs = np.sqrt(np.array([sq[b].sum(0) / cnt[b].sum(0) for b in boot]))
    with warnings.catch_warnings():      # a rate bin no run reached is all NaN: no band, no warning
        warnings.simplefilter("ignore", RuntimeWarning)
        lo, hi = np.nanpercentile(bs, [5, 95], axis=0)
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    xs = np.arange(len(RATE_BINS))
    m = np.isfinite(est)
    ax.errorbar(xs[m], est[m], yerr=[est[m] - lo[m], hi[m] - est[m]], fmt="o", capsize=4)
    ax.set_xticks(xs, RATE_BINS)
    ax.set_xlabel("body rate (deg/s)")
    ax.set_ylabel("1σ per cross-boresight axis (arcsec)")
    ax.set_title(f"attitude error against rate, {n} runs (90 % bootstrap)")
    ax.grid(True, alpha=0.3)
    out.append(_save(fig, folder / "error_vs_rate.png"))

    t = np.array([r["ttff_s"] for r in ok], float)
    t = t[np.isfinite(t)]
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    if t.size:
        counts, edges = np.histogram(t, bins=min(30, max(5, t.size // 5)))
        mid = 0.5 * (edges[:-1] + edges[1:])
        ax.bar(mid, counts, width=np.diff(edges), alpha=0.6)
        ax.errorbar(mid, counts, yerr=np.sqrt(counts), fmt="none", capsize=3, color="k")
    ax.set_xlabel("time to first fix (s)")
    ax.set_ylabel("runs")
    ax.set_title(f"time to first fix, {n} runs ({n - t.size} without a fix; √n error bars)")
    ax.grid(True, alpha=0.3)
    out.append(_save(fig, folder / "ttff_hist.png"))
    return out


def _save(fig, path: Path) -> Path:
    from ...calibration.report import save_figure  # whole or not at all, figure closed

    return save_figure(fig, path)
