"""``gyrostar eval starid``: star-identification Monte Carlo (paper 001, Figs 10–16) on Dask.

Each trial draws a random attitude (uniform on SO(3)) and, for the tracking methods, a
random body rate (uniform direction, magnitude ≤ ``--rate-dps``). Centroids come from
:class:`gyrostar.mocks.star_lists.Sky` (no rendering): catalog stars projected through the
camera, Gaussian position noise (px per axis) and magnitude noise, the sensor limit,
blending of spots closer than 3 px, ``--false-stars`` spurious spots. Paper 001's catalog
noise (0.1 mag, 0.1 px) enters as extra noise on the same difference: the effective
noise is √(PN² + PN_cat²) and √(MN² + MN_cat²).

Tracking trials (``extended-grid``, ``extended-triangle``): frame t is observed at q₀ and
its QUEST attitude (stars matched by truth: the previous identification succeeded) is
propagated with the measured rate ω + b + η over the update period T to predict q₁; the
real attitude is q₁ = exp(ωT) q₀. The gyro error is paper 001's eq. 5 model: b = 1 °/h
per axis (random sign), η ~ N(0, 0.5 °/h) per axis held over T.

Per trial: success (≥ 2 stars identified correctly and none wrongly), any wrong id (and
wrong labels among all labels given),
identification time (centroids → verified result; wall clock ``*_ms`` and the thread's
CPU time ``*_cpu_ms``, which a busy shared machine does not inflate), stars in the field, and the
neighbour-star selection of the reference stars (grid methods): the neighbour chosen in
the observed (or extended C) image is the neighbour the true star's catalog pattern is
oriented on (for the extended grid: one of its ``--orientations``).

Pyramid is given the measured magnitudes with the centroids (its per-star check tests
them; a peer gets them as brightness). ``--peer`` (Pyramid only): each worker also solves its fields with a peer of
:mod:`gyrostar.hil.evaluation.starid_peers` (tetra3rs, or cedar-solve), after ours, on the same centroids
(with their brightness) and a database built for the same field; reported with the ratios
of its median and p99 time to ours, wall and CPU (the process's CPU time for the peer:
under load its wall time waits on thread wake-ups).

Trials run in chunks on a Dask cluster: a LocalCluster (``--workers`` processes, one
thread each) unless ``--scheduler ADDRESS`` names an existing one.
"""

from __future__ import annotations

import dataclasses
import math
import time

import numpy as np

from ...errors import ConfigError
from .starid_peers import PEERS

HELP = "star identification Monte Carlo (paper 001 Figs 10–16): pyramid, grid, extended grid/triangle"
METHODS = ("pyramid", "grid", "extended-grid", "extended-triangle")
SWEEPS = ("fig10", "fig11", "fig12", "fig13", "fig14", "fig15", "fig16")
DPH = math.pi / 180.0 / 3600.0
MAG_SIGMA_FLOOR = 0.2    # mag: the narrowest photometric window Pyramid is given (the paper-001 camera)
LABEL_DEPTH_SIGMA = 3.0  # × the fields' magnitude noise: how far beyond its limit Pyramid's index labels spots
FOV_RANGE_DEG = (1.0, 40.0)      # --fov-deg: a square field's diagonal must stay inside the index's 60° pairs
MAG_LIMIT_RANGE = (2.0, 10.0)    # --mag-limit, V


@dataclasses.dataclass(frozen=True)
class TrialConfig:
    """Everything a worker needs to run trials (hashable: workers cache their setup by it)."""

    method: str = "extended-grid"
    preset: str = "qian2015"
    fov_deg: float = 0.0
    pixels: int = 1024
    catalog: str = "hip2"
    mag_limit: float = 7.5
    per_field: int = -1
    pos_noise_px: float = 1.0
    mag_noise: float = 0.2
    cat_pos_noise_px: float = 0.1
    cat_mag_noise: float = 0.1
    false_stars: int = 0
    update_period_s: float = 1.0
    rate_dps: float = 0.5
    bias_dph: float = 1.0
    random_dph: float = 0.5
    orientations: int = 3
    xi: int = 4
    peer: str = ""
    p_false_max: float = 1e-6

    @property
    def total_pos_noise(self) -> float:
        return math.hypot(self.pos_noise_px, self.cat_pos_noise_px)

    @property
    def total_mag_noise(self) -> float:
        return math.hypot(self.mag_noise, self.cat_mag_noise)


def configure(parser) -> None:
    from ...cli.argtypes import positive_float
    from ...cli.argtypes import seed as seed_type
    from ...cli.main import add_json
    from .plot_target import png_file_or_folder

    d = TrialConfig()
    parser.add_argument("--method", choices=METHODS, default=d.method,
                        help="identifier under test (default %(default)s)")
    parser.add_argument("--preset", default=d.preset, help="camera preset: qian2015, xing2012 (default %(default)s)")
    parser.add_argument("--fov-deg", type=float, default=0.0,
                        help="square camera of this full field, deg (1 … 40), instead of the preset (with --pixels; "
                             "default 0: the preset's)")
    parser.add_argument("--pixels", type=int, default=None,
                        help=f"pixels across, with --fov-deg (default {d.pixels})")
    parser.add_argument("--catalog", choices=("hip2", "gaia"), default=d.catalog,
                        help="star catalog (default %(default)s)")
    parser.add_argument("--mag-limit", type=float, default=d.mag_limit,
                        help="sensor limiting V magnitude (default %(default)s)")
    parser.add_argument("--per-field", type=int, default=-1,
                        help="navigation stars per field for Pyramid (default -1: 12 for gaia, all for hip2)")
    parser.add_argument("--position-noise-px", type=float, default=d.pos_noise_px,
                        help="Gaussian centroid noise per axis, px (default %(default)s)")
    parser.add_argument("--mag-noise", type=float, default=d.mag_noise,
                        help="Gaussian noise on measured magnitudes, mag (default %(default)s)")
    parser.add_argument("--catalog-position-noise-px", type=float, default=d.cat_pos_noise_px,
                        help="Gaussian noise on catalog positions, px equivalent (default %(default)s)")
    parser.add_argument("--catalog-mag-noise", type=float, default=d.cat_mag_noise,
                        help="Gaussian noise on catalog magnitudes, mag (default %(default)s)")
    parser.add_argument("--false-stars", type=int, default=0,
                        help="spurious spots added per field (default %(default)s)")
    parser.add_argument("--update-period-s", type=float, default=d.update_period_s,
                        help="tracking: time between identifications, s (default %(default)s)")
    parser.add_argument("--rate-dps", type=float, default=d.rate_dps,
                        help="largest body rate, °/s (default %(default)s)")
    parser.add_argument("--gyro-bias-dph", type=float, default=d.bias_dph,
                        help="tracking: gyro constant drift, °/h (default %(default)s)")
    parser.add_argument("--gyro-random-dph", type=float, default=d.random_dph,
                        help="tracking: gyro random drift, °/h (default %(default)s)")
    parser.add_argument("--orientations", type=int, default=d.orientations,
                        help="extended grid: catalog pattern orientations per candidate (1 = plain rule; "
                             "default %(default)s)")
    parser.add_argument("--xi", type=int, default=d.xi, help="grid: minimum shared cells ξ (default %(default)s)")
    parser.add_argument("--p-false-max", type=float, default=d.p_false_max, metavar="P",
                        help="pyramid: largest expected false-match count it accepts, in (0, 1) (default "
                             "%(default)g; larger trades safety for sparse fields, see docs/RELIABILITY.md)")
    parser.add_argument("--peer", nargs="?", const="tetra3rs", default="", choices=PEERS,
                        help="pyramid: also solve every field with this peer (tetra3rs when given alone, or "
                             "cedar-solve) in the same worker, after ours (default: none)")
    parser.add_argument("--trials", type=int, default=1000,
                        help="Monte Carlo trials (per sweep point with --sweep; default %(default)s)")
    parser.add_argument("--seed", type=seed_type, default=1, help="random seed (default %(default)s)")
    parser.add_argument("--scheduler", default=None, help="address of an existing Dask scheduler, e.g. tcp://host:8786 "
                             "(default: a LocalCluster on this machine)")
    parser.add_argument("--scheduler-timeout", type=positive_float, default=5.0, metavar="S",
                        help="seconds to wait for --scheduler to answer (default %(default)s)")
    parser.add_argument("--workers", type=int, default=2, help="LocalCluster worker processes (default %(default)s)")
    parser.add_argument("--sweep", choices=SWEEPS + ("all",), default=None,
                        help="reproduce a figure of paper 001 (trials per point = --trials; default: none)")
    parser.add_argument("--plot", type=png_file_or_folder, default=None, metavar="PATH",
                        help="with --sweep: write the sweep's figure(s) as PNG (a .png name for one figure, or a "
                             "folder; default: none)")
    add_json(parser)


def config_from_args(args) -> TrialConfig:
    if args.pixels is not None and not args.fov_deg:
        raise ConfigError("--pixels sets the sensor of a --fov-deg camera; a preset has its own (give --fov-deg too)")
    if args.peer and args.method != "pyramid":
        raise ConfigError(f"--peer compares lost-in-space solvers: it needs --method pyramid (got {args.method})")
    if args.plot and not args.sweep:
        raise ConfigError("--plot writes the figures of a --sweep (give --sweep figNN or all)")
    if args.plot and args.plot.lower().endswith(".png") and args.sweep == "all":
        raise ConfigError("--plot FILE.png holds one figure and --sweep all makes several: give a folder")
    pixels = TrialConfig.pixels if args.pixels is None else args.pixels
    cfg = TrialConfig(args.method, args.preset, args.fov_deg, pixels, args.catalog, args.mag_limit,
                      args.per_field, args.position_noise_px, args.mag_noise, args.catalog_position_noise_px,
                      args.catalog_mag_noise, args.false_stars, args.update_period_s, args.rate_dps,
                      args.gyro_bias_dph, args.gyro_random_dph, args.orientations, args.xi, args.peer,
                      args.p_false_max)
    validate(cfg)
    return cfg


def validate(cfg: TrialConfig) -> None:
    if cfg.method not in METHODS:
        raise ConfigError(f"unknown method {cfg.method!r} (known: {', '.join(METHODS)})")
    for name in ("pos_noise_px", "mag_noise", "cat_pos_noise_px", "cat_mag_noise", "rate_dps",
                 "bias_dph", "random_dph"):
        if not (getattr(cfg, name) >= 0 and math.isfinite(getattr(cfg, name))):
            raise ConfigError(f"{name} must be a finite number ≥ 0, got {getattr(cfg, name)!r}")
    if cfg.false_stars < 0 or cfg.update_period_s <= 0 or cfg.orientations < 1 or cfg.xi < 1:
        raise ConfigError("false stars ≥ 0, update period > 0, orientations ≥ 1 and xi ≥ 1 are required")
    if not 0.0 < cfg.p_false_max < 1.0:
        raise ConfigError(f"--p-false-max must be in (0, 1), got {cfg.p_false_max!r}")
    if not (math.isfinite(cfg.mag_limit) and MAG_LIMIT_RANGE[0] <= cfg.mag_limit <= MAG_LIMIT_RANGE[1]):
        lo, hi = MAG_LIMIT_RANGE
        raise ConfigError(f"--mag-limit must be in [{lo:g}, {hi:g}], got {cfg.mag_limit!r}")
    if cfg.fov_deg and not (FOV_RANGE_DEG[0] <= cfg.fov_deg <= FOV_RANGE_DEG[1] and 16 <= cfg.pixels <= 16384):
        raise ConfigError(f"--fov-deg must be in [{FOV_RANGE_DEG[0]:g}, {FOV_RANGE_DEG[1]:g}] with --pixels in "
                          f"[16, 16384], got {cfg.fov_deg}, {cfg.pixels}")
    try:
        trial_camera(cfg)
    except ConfigError as exc:
        raise ConfigError(f"--preset: {exc}") from None


# ---------------------------------------------------------------- worker side
_SETUP: dict = {}


def trial_camera(cfg: TrialConfig):
    """The camera of a trial configuration: a pinhole for ``--fov-deg``, else the preset."""
    from ...camera import camera_preset
    from ...mocks.star_lists import camera_for_fov

    return camera_for_fov(cfg.fov_deg, cfg.pixels) if cfg.fov_deg else camera_preset(cfg.preset)


def setup(cfg: TrialConfig) -> dict:
    """Camera, sky, index and identifier of a configuration (cached per process)."""
    # fields of any noise share a setup, but the identifier's tolerances follow the noise
    sigma = max(cfg.total_pos_noise, 0.3)
    # measured magnitudes in the search and the bound, never trusted beyond the paper-001
    # camera's 0.2 mag (a field generated with exact magnitudes still gets a 0.2 mag window)
    sigma_mag = max(cfg.total_mag_noise, MAG_SIGMA_FLOOR)
    # the sensor sees stars up to ~3σ of its magnitude noise fainter than its limit: the
    # index holds them to label spots (none when the fields' magnitudes are exact)
    label_depth = round(LABEL_DEPTH_SIGMA * cfg.total_mag_noise, 1)
    key = (dataclasses.replace(cfg, pos_noise_px=0.0, mag_noise=0.0, cat_pos_noise_px=0.0, cat_mag_noise=0.0,
                               update_period_s=1.0, false_stars=0), sigma, sigma_mag, label_depth)
    if key in _SETUP:
        return _SETUP[key]
    from ...catalog import deepest_limit, load_catalog
    from ...mocks.star_lists import Sky
    from ...starid.extended import ExtendedIdentifier
    from ...starid.grid import GridIdentifier, GridParams, load_grid_database
    from ...starid.index import load_index
    from ...starid.lost_in_space import build_pyramid

    cam = trial_camera(cfg)
    diag = 2.0 * math.degrees(math.atan(0.5 * math.hypot(cam.width_px, cam.height_px) / cam.focal_length_px))
    deep = load_catalog(cfg.catalog, deepest_limit(cfg.catalog, cfg.mag_limit + 1.0))
    sky = Sky(deep)
    out = {"camera": cam, "sky": sky}
    if cfg.method == "pyramid":
        per_field = cfg.per_field if cfg.per_field >= 0 else (12 if cfg.catalog == "gaia" else 0)
        sep = round(diag + 0.01, 3)
        # navigation stars to the sensor's limit (stars label_depth fainter label spots too), the
        # thinned first tier, and the faint stars the index leaves out: the public builder
        out["ident"] = build_pyramid(cam, cfg.catalog, cfg.mag_limit, per_field=per_field, label_depth_mag=label_depth,
                                     sigma_px=sigma, sigma_mag=sigma_mag, p_false_max=cfg.p_false_max,
                                     max_sep_deg=sep)
        if cfg.peer:
            from .starid_peers import load_peer

            out["peer"] = load_peer(cfg.peer, cam, cfg.mag_limit, cfg.catalog)
    elif cfg.method == "grid":
        params = GridParams(xi=cfg.xi)
        sep = round(max(diag, math.degrees(params.pr) * 2 ** 0.5) + 0.01, 3)
        index = load_index(cfg.catalog, cfg.mag_limit, sep, 0)
        db = load_grid_database(index, params)
        out["ident"] = GridIdentifier(index, db, cam, sigma_px=sigma)
    else:
        # index deeper than the sensor: the ambiguity check sees faint close companions
        index = load_index(cfg.catalog, cfg.mag_limit + 0.5, round(diag + 0.01, 3), 0)
        out["ident"] = ExtendedIdentifier(index, cam, GridParams(xi=cfg.xi), method=cfg.method.split("-")[1],
                                          mag_max=cfg.mag_limit, sigma_px=sigma, n_orient=cfg.orientations)
    out["index"] = out["ident"].index
    out["row_of_id"] = {int(i): k for k, i in enumerate(out["index"].ids)}
    _SETUP[key] = out
    _warm_up(cfg, out)
    return out


def _warm_up(cfg: TrialConfig, s: dict) -> None:
    """One untimed identification, so that loading compiled code is not in the timings."""
    from ...attitude import quat_from_boresight

    q = quat_from_boresight(1.0, 0.3, 0.2)
    frame = s["sky"].observe(s["camera"], q, cfg.mag_limit, 0.0, 0.0, 0, np.random.default_rng(0))
    if cfg.method.startswith("extended"):
        s["ident"].identify(frame.uv, q)
    else:
        s["ident"].identify(frame.uv)


def gyro_prediction(q0_est, omega, cfg, rng):
    from ...attitude import quat_propagate

    bias = cfg.bias_dph * DPH * rng.choice([-1.0, 1.0], 3)
    eta = rng.normal(0.0, cfg.random_dph * DPH, 3)
    return quat_propagate(q0_est, omega + bias + eta, cfg.update_period_s)


def run_chunk(cfg: TrialConfig, seed: int, n: int) -> dict:
    """Run ``n`` trials; per-trial arrays (seeded, reproducible)."""
    from ...attitude import quat_propagate, quat_to_dcm, random_attitudes
    from ...mocks.star_lists import score
    from ...starid.verify import solve

    s = setup(cfg)
    cam, sky, ident, index, row_of = s["camera"], s["sky"], s["ident"], s["index"], s["row_of_id"]
    rng = np.random.default_rng(seed)
    pn, mn = cfg.total_pos_noise, cfg.total_mag_noise
    keys = ("success", "wrong", "n_stars", "ms", "cpu_ms", "nb_ok", "nb_total", "gyro_err_px", "peer_solved",
            "peer_correct", "peer_ms", "peer_cpu_ms", "labels", "wrong_labels")
    res = {k: [] for k in keys}
    tracking = cfg.method.startswith("extended")
    # every field first (same random stream as one trial after another: identifying draws
    # nothing), then the identifications back to back, like the peer's below
    trials = []
    for q in random_attitudes(n, rng):
        gyro_err = math.nan
        q_pred = None
        if tracking:
            axis = rng.normal(size=3)
            omega = axis / np.linalg.norm(axis) * math.radians(rng.uniform(0.0, cfg.rate_dps))
            f0 = sky.observe(cam, q, cfg.mag_limit, pn, mn, 0, rng)
            m0 = np.array([row_of.get(int(t), -1) for t in f0.truth], dtype=np.int64)
            q0 = solve(cam.unproject(f0.uv), index.vectors, m0) if np.count_nonzero(m0 >= 0) >= 2 else q
            q_true = quat_propagate(q, omega, cfg.update_period_s)
            q_pred = gyro_prediction(q0, omega, cfg, rng)
            frame = sky.observe(cam, q_true, cfg.mag_limit, pn, mn, cfg.false_stars, rng)
            # gyro-only prediction error at the boresight, px (paper 001 eq. 6 / Fig. 16)
            q_gyro = gyro_prediction(q, omega, cfg, rng)
            gyro_err = math.acos(min(1.0, float(quat_to_dcm(q_gyro)[2] @ quat_to_dcm(q_true)[2]))) \
                * cam.focal_length_px
        else:
            frame = sky.observe(cam, q, cfg.mag_limit, pn, mn, cfg.false_stars, rng)
        trials.append((frame, q_pred, gyro_err))
    for frame, q_pred, gyro_err in trials:
        t0, c0 = time.perf_counter(), time.thread_time()
        if tracking:
            r = ident.identify(frame.uv, q_pred)
        elif cfg.method == "pyramid":
            r = ident.identify(frame.uv, mag=frame.mag)   # measured magnitudes: its search and per-star check
        else:
            r = ident.identify(frame.uv)                  # the grid baseline matches positions only
        dt, dc = time.perf_counter() - t0, time.thread_time() - c0
        c, w = score(r.ids, frame.truth, frame.alt)
        res["success"].append(c >= 2 and w == 0)
        res["wrong"].append(w > 0)
        res["labels"].append(c + w)
        res["wrong_labels"].append(w)
        res["n_stars"].append(int(np.count_nonzero(frame.truth >= 0)))
        res["ms"].append(dt * 1e3)
        res["cpu_ms"].append(dc * 1e3)
        ok, tot = _neighbour_stats(cfg, ident, frame, index, row_of)
        res["nb_ok"].append(ok)
        res["nb_total"].append(tot)
        res["gyro_err_px"].append(gyro_err)
    peer_frames = [t[0] for t in trials] if cfg.method == "pyramid" and cfg.peer and \
        not isinstance(s.get("peer"), str) else []
    # the peer solves the same fields after ours, so neither runs on the other's cold caches
    if peer_frames:
        from .starid_peers import score_peer

        peer = s["peer"]
        peer.solve(peer_frames[0].uv, peer_frames[0].mag, cam)  # untimed: loads the peer's code and data
    for frame in peer_frames:
        solved, ids, r_est, ms, cpu = peer.solve(frame.uv, frame.mag, cam)
        solved, correct = score_peer(peer, solved, ids, r_est, frame, cam)
        res["peer_solved"].append(solved)
        res["peer_correct"].append(correct)
        res["peer_ms"].append(ms)
        res["peer_cpu_ms"].append(cpu)
    out = {k: np.asarray(v) for k, v in res.items()}
    if cfg.peer and isinstance(s.get("peer"), str):
        out["peer_reason"] = s["peer"]
    elif peer_frames:
        out["peer_name"] = s["peer"].name
    return out


def _neighbour_stats(cfg, ident, frame, index, row_of) -> tuple[int, int]:
    """(references whose neighbour selection matched the true star's pattern, references)."""
    if cfg.method == "pyramid":
        return 0, 0
    ok = tot = 0
    ids = index.ids
    if cfg.method == "grid":
        b = ident.camera.unproject(frame.uv) if frame.uv.size else np.empty((0, 3))
        _, nb_obs = ident.identify_vectors(b)
        for r in range(min(len(frame.uv), ident.max_ref)):
            row = row_of.get(int(frame.truth[r]), -1)
            if frame.truth[r] < 0 or row < 0:
                continue
            tot += 1
            want = ident.db.neighbour[row]
            if nb_obs[r] >= 0 and want >= 0 and frame.truth[nb_obs[r]] == ids[want]:
                ok += 1
        return ok, tot
    match, nb_c, c_cat, cand_cat, pat_nb = ident.last
    cand_ids = ids[cand_cat] if cand_cat.size else cand_cat
    for r in range(min(len(frame.uv), ident.max_ref)):
        t = frame.truth[r]
        if t < 0:
            continue
        hit = np.flatnonzero(cand_ids == t)
        if hit.size == 0:
            continue
        tot += 1
        nb = nb_c[r]
        if nb < 0:
            continue
        got = ids[c_cat[nb]] if c_cat[nb] >= 0 else frame.truth[nb]
        want = pat_nb[hit[0]]
        if got >= 0 and np.any((want >= 0) & (ids[np.maximum(want, 0)] == got)):
            ok += 1
    return ok, tot


# ---------------------------------------------------------------- driver side
def summarize(chunks: list[dict]) -> dict:
    """Aggregate chunk arrays into the reported figures."""
    cat = {k: np.concatenate([c[k] for c in chunks]) for k in chunks[0] if k not in ("peer_reason", "peer_name")}
    n = int(cat["success"].size)
    ms = cat["ms"]
    nb_total = int(cat["nb_total"].sum())
    out = {
        "trials": n,
        "success_rate": float(cat["success"].mean()) if n else math.nan,
        "false_id_rate": float(cat["wrong"].mean()) if n else math.nan,
        "false_ids": int(cat["wrong"].sum()),
        "wrong_label_rate": float(cat["wrong_labels"].sum() / max(1, cat["labels"].sum())),
        "neighbor_success_rate": float(cat["nb_ok"].sum() / nb_total) if nb_total else math.nan,
        "median_ms": float(np.median(ms)) if n else math.nan,
        "p99_ms": float(np.percentile(ms, 99)) if n else math.nan,
        "median_cpu_ms": float(np.median(cat["cpu_ms"])) if n else math.nan,
        "p99_cpu_ms": float(np.percentile(cat["cpu_ms"], 99)) if n else math.nan,
        "fields_under_2_stars": float(np.mean(cat["n_stars"] < 2)) if n else math.nan,
        "star_count_histogram": np.bincount(np.minimum(cat["n_stars"], 7), minlength=8).tolist(),
    }
    g = cat["gyro_err_px"]
    if np.any(np.isfinite(g)):
        out["gyro_error_px_rms"] = float(np.sqrt(np.nanmean(g ** 2)))
    if cat["peer_ms"].size:
        pm, p99 = float(np.median(cat["peer_ms"])), float(np.percentile(cat["peer_ms"], 99))
        pc, pc99 = float(np.median(cat["peer_cpu_ms"])), float(np.percentile(cat["peer_cpu_ms"], 99))
        out["peer"] = {"name": next(c["peer_name"] for c in chunks if "peer_name" in c),
                       "success_rate": float(cat["peer_correct"].mean()),
                       "wrong_rate": float(np.mean(cat["peer_solved"] & ~cat["peer_correct"])),
                       "median_ms": pm, "p99_ms": p99, "median_cpu_ms": pc, "p99_cpu_ms": pc99,
                       "median_ratio": pm / out["median_ms"], "p99_ratio": p99 / out["p99_ms"],
                       "median_cpu_ratio": pc / out["median_cpu_ms"], "p99_cpu_ratio": pc99 / out["p99_cpu_ms"]}
    reasons = [c["peer_reason"] for c in chunks if "peer_reason" in c]
    if reasons:
        out["peer"] = {"skipped": reasons[0]}
    return out


class Runner:
    """Submits trial chunks to a Dask cluster (local unless an address is given)."""

    def __init__(self, scheduler: str | None, workers: int, connect_timeout_s: float = 5.0):
        from ..dask_quiet import distributed, local_client, quiet_worker_plugin, silence_logs

        self.cluster = None
        if scheduler:
            silence_logs()
            try:
                self.client = distributed().Client(scheduler, timeout=connect_timeout_s)
            except (OSError, TimeoutError, ValueError) as exc:
                from ...errors import DeviceError

                raise DeviceError(f"--scheduler {scheduler}: no Dask scheduler answered within "
                                  f"{connect_timeout_s:g} s ({type(exc).__name__})") from exc
        else:
            self.cluster, self.client = local_client(workers)
            self.client.register_plugin(quiet_worker_plugin())

    def run(self, cfg: TrialConfig, trials: int, seed: int, advance=None) -> dict:
        from dask.distributed import as_completed

        if trials < 1:
            raise ConfigError(f"--trials must be ≥ 1, got {trials}")
        size = max(10, min(250, trials // 8 or 1))
        seeds = np.random.SeedSequence(seed).spawn((trials + size - 1) // size)
        futures = []
        left = trials
        for k, ss in enumerate(seeds):
            n = min(size, left)
            left -= n
            futures.append(self.client.submit(run_chunk, cfg, int(ss.generate_state(1)[0]), n,
                                              key=f"starid-{hash(cfg) & 0xffffffff:x}-{seed}-{k}"))
        chunks = []
        try:
            for fut in as_completed(futures):
                chunk = fut.result()
                chunks.append(chunk)
                if advance:
                    advance(int(chunk["success"].size))
        finally:
            for f in futures:
                f.cancel()
        return summarize(chunks)

    def close(self) -> None:
        self.client.close()
        if self.cluster is not None:
            self.cluster.close()


def run(args) -> int:
    from ...cli.output import emit, progress

    cfg = config_from_args(args)
    if args.trials < 1:
        raise ConfigError(f"--trials must be ≥ 1, got {args.trials}")
    runner = Runner(args.scheduler, args.workers, args.scheduler_timeout)
    try:
        if args.sweep:
            from .starid_figures import run_sweeps

            result = run_sweeps(args, cfg, runner)
            emit(args, result, _sweep_text(result))
            return 0
        with progress(args, f"starid {cfg.method}", args.trials) as advance:
            result = runner.run(cfg, args.trials, args.seed, advance)
    finally:
        runner.close()
    result = {"method": cfg.method, "config": dataclasses.asdict(cfg), **result}
    emit(args, result, _text(result))
    return 0


def _text(r: dict) -> str:
    lines = [f"{r['method']}: {r['trials']} trials",
             f"  success {100 * r['success_rate']:.2f} %   false ids {r['false_ids']} "
             f"({100 * r['false_id_rate']:.3f} % of fields; {100 * r['wrong_label_rate']:.4f} % of labels)",
             f"  neighbour selection {100 * r['neighbor_success_rate']:.2f} %" if
             math.isfinite(r["neighbor_success_rate"]) else "  neighbour selection n/a",
             f"  time median {r['median_ms']:.3f} ms  p99 {r['p99_ms']:.3f} ms (wall);  "
             f"CPU median {r['median_cpu_ms']:.3f} ms  p99 {r['p99_cpu_ms']:.3f} ms",
             f"  fields with < 2 stars {100 * r['fields_under_2_stars']:.2f} %"]
    if "peer" in r:
        p = r["peer"]
        lines.append(f"  peer: skipped ({p['skipped']})" if "skipped" in p else
                     f"  peer {p['name']}: success {100 * p['success_rate']:.2f} %  wrong "
                     f"{100 * p['wrong_rate']:.2f} %\n"
                     f"    time median {p['median_ms']:.3f} ms ({p['median_ratio']:.2f}× ours)  "
                     f"p99 {p['p99_ms']:.3f} ms ({p['p99_ratio']:.2f}× ours) (wall);  "
                     f"CPU median {p['median_cpu_ms']:.3f} ms ({p['median_cpu_ratio']:.2f}× ours)  "
                     f"p99 {p['p99_cpu_ms']:.3f} ms ({p['p99_cpu_ratio']:.2f}× ours)")
    return "\n".join(lines)


def _sweep_text(r: dict) -> str:
    lines = []
    for fig, data in r.get("figures", {}).items():
        lines.append(f"{fig}: {data['title']}")
        for series, pts in data["series"].items():
            lines.append(f"  {series}: " + ", ".join(f"{x:g}→{y:.4g}" for x, y in zip(data["x"], pts)))
    for path in r.get("plots", []):
        lines.append(f"wrote {path}")
    return "\n".join(lines)
