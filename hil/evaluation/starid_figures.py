"""Sweeps that reproduce paper 001's Figures 10–16 (``gyrostar eval starid --sweep``).

fig10  success vs position noise (MN 0.2): extended grid vs extended triangle
fig11  success vs magnitude noise (PN 0.3): extended grid vs extended triangle
fig12  extended-grid success vs position noise (update period 1 s)
fig13  star-count distribution of the real field (Table 1 / Fig. 13)
fig14  neighbour-star selection vs position noise: extended grid (paper's single
       orientation and ours) vs the plain grid
fig15  extended-grid success vs update period (PN 0.3)
fig16  gyro-induced position error vs update period: simulated rms at the boresight and
       eq. 6's value √2·b·T·f (px; b the constant drift per axis)
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np

from ...errors import ConfigError

PN_POINTS = (0.0, 0.25, 0.5, 0.75, 1.0, 1.5, 2.0)
MN_POINTS = (0.0, 0.1, 0.2, 0.3, 0.4, 0.5)
T_POINTS = (0.1, 0.5, 1.0, 2.0, 5.0, 10.0)


def _series(runner, base, trials, seed, field, xs, key, advance, **over):
    ys = []
    for x in xs:
        cfg = dataclasses.replace(base, **{field: x}, **over)
        r = runner.run(cfg, trials, seed)
        ys.append(r[key])
        advance(1)
    return ys


def run_sweeps(args, base, runner) -> dict:
    """Run the chosen sweep(s); returns ``{"figures": {...}, "plots": [...]}``."""
    from ...cli.output import progress

    figs = ("fig10", "fig11", "fig12", "fig13", "fig14", "fig15", "fig16") if args.sweep == "all" else (args.sweep,)
    base = dataclasses.replace(base, method="extended-grid", false_stars=0)
    n, seed = args.trials, args.seed
    points = {"fig10": 2 * len(PN_POINTS), "fig11": 2 * len(MN_POINTS), "fig12": len(PN_POINTS), "fig13": 1,
              "fig14": 3 * len(PN_POINTS), "fig15": len(T_POINTS), "fig16": len(T_POINTS)}
    out: dict = {"figures": {}, "plots": []}
    with progress(args, "starid sweeps", sum(points[f] for f in figs)) as adv:
        for fig in figs:
            if fig in ("fig10", "fig11"):
                key, pts, fixed, title, xlabel = (
                    ("pos_noise_px", PN_POINTS, {"mag_noise": 0.2}, "success vs position noise (MN 0.2)",
                     "position noise (px)") if fig == "fig10" else
                    ("mag_noise", MN_POINTS, {"pos_noise_px": 0.3}, "success vs magnitude noise (PN 0.3 px)",
                     "magnitude noise"))
                b = dataclasses.replace(base, **fixed)
                out["figures"][fig] = {"title": title, "xlabel": xlabel, "ylabel": "success rate", "x": list(pts),
                                       "series": {
                    "extended grid": _series(runner, b, n, seed, key, pts, "success_rate", adv),
                    "extended triangle": _series(runner, b, n, seed, key, pts, "success_rate", adv,
                                                 method="extended-triangle")}}
            elif fig == "fig12":
                out["figures"][fig] = {"title": "extended grid success vs position noise (T = 1 s)",
                                       "xlabel": "position noise (px)", "ylabel": "success rate",
                                       "x": list(PN_POINTS), "series": {
                    "extended grid": _series(runner, dataclasses.replace(base, update_period_s=1.0), n, seed,
                                             "pos_noise_px", PN_POINTS, "success_rate", adv)}}
            elif fig == "fig13":
                r = runner.run(dataclasses.replace(base, pos_noise_px=0.0, mag_noise=0.0), n, seed)
                adv(1)
                hist = np.asarray(r["star_count_histogram"], dtype=float)
                out["figures"][fig] = {"title": "stars in the real field", "xlabel": "stars (7 = ≥ 7)",
                                       "ylabel": "fraction of fields", "x": list(range(8)),
                                       "series": {"fields": (hist / max(hist.sum(), 1)).tolist()}, "bar": True}
            elif fig == "fig14":
                out["figures"][fig] = {"title": "neighbour-star selection vs position noise",
                                       "xlabel": "position noise (px)", "ylabel": "neighbour selection success",
                                       "x": list(PN_POINTS), "series": {
                    f"extended grid ({base.orientations} orientations)": _series(
                        runner, base, n, seed, "pos_noise_px", PN_POINTS, "neighbor_success_rate", adv),
                    "extended grid (1 orientation, paper)": _series(
                        runner, base, n, seed, "pos_noise_px", PN_POINTS, "neighbor_success_rate", adv,
                        orientations=1),
                    "grid": _series(runner, base, n, seed, "pos_noise_px", PN_POINTS, "neighbor_success_rate", adv,
                                    method="grid")}}
            elif fig == "fig15":
                out["figures"][fig] = {"title": "extended grid success vs update period (PN 0.3 px)",
                                       "xlabel": "update period (s)", "ylabel": "success rate", "x": list(T_POINTS),
                                       "series": {"extended grid": _series(
                                           runner, dataclasses.replace(base, pos_noise_px=0.3), n, seed,
                                           "update_period_s", T_POINTS, "success_rate", adv)}}
            elif fig == "fig16":
                from .eval_starid import DPH, trial_camera

                f_px = trial_camera(base).focal_length_px
                sim = _series(runner, dataclasses.replace(base, pos_noise_px=0.3), n, seed, "update_period_s",
                              T_POINTS, "gyro_error_px_rms", adv)
                eq6 = [math.sqrt(2.0 * (base.bias_dph ** 2 + base.random_dph ** 2)) * DPH * t * f_px
                       for t in T_POINTS]
                out["figures"][fig] = {"title": "gyro-induced position error vs update period",
                                       "xlabel": "update period (s)", "ylabel": "position error (px)",
                                       "x": list(T_POINTS), "series": {"simulated (rms)": sim, "eq. 6": eq6}}
    if args.plot:
        out["plots"] = plot(out["figures"], Path(args.plot))
    return out


def plot(figures: dict, target: Path) -> list[str]:
    """Write one PNG per figure; ``target`` is a folder, or a file name when one figure."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    if len(figures) == 1 and target.suffix.lower() == ".png":
        paths = {next(iter(figures)): target}
    else:
        if target.suffix:
            raise ConfigError(f"--plot for several figures must be a folder, got {target}")
        target.mkdir(parents=True, exist_ok=True)
        paths = {name: target / f"starid_{name}.png" for name in figures}
    written = []
    for name, fig in figures.items():
        paths[name].parent.mkdir(parents=True, exist_ok=True)
        f, ax = plt.subplots(figsize=(6, 4), dpi=120)
        for label, ys in fig["series"].items():
            if fig.get("bar"):
                ax.bar(fig["x"], ys, label=label)
            else:
                ax.plot(fig["x"], ys, marker="o", label=label)
        ax.set_xlabel(fig["xlabel"])
        ax.set_ylabel(fig["ylabel"])
        ax.set_title(f"{name}: {fig['title']}")
        ax.grid(True, alpha=0.3)
        ax.legend()
        f.tight_layout()
        f.savefig(paths[name])
        plt.close(f)
        written.append(str(paths[name]))
    return written
