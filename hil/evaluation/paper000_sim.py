"""Paper 000's simulations (Xing et al. 2012, sim1..sim4) on the simulator, three ways.

One Mv 5 star (``xing2012`` preset: F = 100 mm, D = 80 mm, T = 0.85, 10 ms exposures at
100 Hz, 1024² × 15 µm) is tracked frame by frame by

* (A) ``fixed_window`` — the traditional method: a k×k window centred on the last
  centroid, thresholded centre of gravity;
* (B) ``gyro_window`` — paper 000 §2: the union of k×k squares along the trajectory
  predicted from the last centroid and the raw gyro rates of the exposure, CoG;
* (C) ``ekf`` — paper 000 §3: the spot EKF (predicted at every 400 Hz gyro sample) sets
  the trajectory window from its estimate and drift-corrected rates, and is updated with
  the window's centroid at mid-exposure (the centroid of a smeared spot is the
  exposure-averaged position), then re-propagated to the present. Its centroid is the
  least-squares fit of the PSF smeared along the predicted path (``centroid.smear_fit``,
  measured best: sim3 0.11 px against 0.14 px for the weighted CoG and 0.15 px for CoG),
  with the fit's covariance as the measurement noise.

The windows are read out by the simulator (``gyrostar.mocks.sky.Sky.readout_windows``)
from the true attitude (``gyrostar.mocks.trajectory``); the gyro samples come from
``gyrostar.mocks.gyro_truth`` (parameter set ``xing2012``: drift 0.02 °/s per axis,
BMI088-class white noise 0.014 °/s/√Hz, 47 Hz filter, ±125 °/s range quantisation), each
sample held over the 2.5 ms interval it ends. The rotation carries a star across the 8.8° field in
about a second at 8 °/s: when the tracked star nears the edge, a new Mv 5 star entering
on the far side is acquired (all three methods start from the same acquisition
centroid on a window of 2k-px squares along the path predicted from the catalog position,
known to ~0.5 px, and the gyro; the EKF keeps its drift estimate through the reset path).

A frame is *lost* by a method when its centroid is missing or more than ``lost_px``
from the truth (exposure-averaged centroid). Errors are px, per axis.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from ...attitude import quat_conj, quat_from_boresight, quat_mult, quat_to_dcm
from ...core.centroid import (
    background_far,
    centroid_variance,
    cog,
    iwcog,
    iwcog_variance,
    smear_fit,
    suppress_isolated,
)
from ...core.crlb import mortensen_crlb_px
from ...core.motion import MODEL_FIRST_ORDER, MODEL_PINHOLE, predict_trajectory, substeps_for
from ...core.spot_ekf import (
    CHI2_2DOF_999,
    spot_ekf_init,
    spot_ekf_propagate,
    spot_ekf_reset,
    spot_ekf_update,
)
from ...core.windows import concat_windows, fixed_window, trajectory_window
from ...errors import ConfigError

DEG = math.pi / 180.0
SCENARIOS = ("sim1", "sim2", "sim3", "sim4")
CENTROIDS = ("fit", "iwcog", "cog")
GYRO_NOISE_MAX_DPS_RTHZ = 1.0   # °/s/√Hz: --gyro-noise-dps-rthz above it is no gyro (MEMS ~0.01)


@dataclasses.dataclass(frozen=True)
class Paper000Config:
    """Settings of one run (units in the names)."""

    scenario: str = "sim2"
    max_rate_dps: float | None = None      # sim1 only: rate at the end of the ramp (paper: 8)
    seed: int = 0
    vmag: float = 5.0
    window_k: int = 6                      # paper: 6×6 squares
    fixed_k: int = 6                       # traditional window side
    gyro_hz: float = 400.0
    gyro: str = "xing2012"                 # gyrostar.mocks.gyro_truth parameter set (paper: drift 0.02 °/s)
    gyro_noise_dps_rthz: float | None = None  # override of the set's white-noise density (°/s/√Hz)
    bias_rw_dps_rts: float = 1e-5          # drift random-walk density the EKF assumes
    centroid: str = "fit"                  # C's centroid: "fit" (smeared-PSF LSQ), "iwcog" or "cog"
    model: str = "pinhole"                 # C's motion model: "pinhole" or "first_order"
    threshold_sigma: float = 3.0
    iwcog_sigma_px: float = 1.0
    offset_stride: int = 1
    lost_px: float = 1.0
    isolated_neighbours: int = 1           # drop above-threshold pixels with fewer such neighbours (0: off)
    spike_ratio: float = 4.0               # drop pixels brighter than this × their brightest neighbour (0: off)
    start_xy_px: tuple[float, float] = (150.0, 100.0)
    edge_px: float = 430.0                 # hand over when the star is this far from the centre
    max_coast_frames: int = 5              # frames without an accepted update before re-acquiring

    def validate(self) -> None:
        if self.scenario not in SCENARIOS:
            raise ConfigError(f"unknown scenario '{self.scenario}' (known: {', '.join(SCENARIOS)})")
        if self.max_rate_dps is not None and not 0 < self.max_rate_dps <= 60:
            raise ConfigError("--max-rate-dps must be in (0, 60] °/s")
        if self.centroid not in CENTROIDS:
            raise ConfigError(f"centroid must be one of {CENTROIDS}")
        if self.model not in ("pinhole", "first_order"):
            raise ConfigError("model must be 'pinhole' or 'first_order'")
        if not 2 <= self.window_k <= 32 or not 2 <= self.fixed_k <= 64:
            raise ConfigError("window sizes must be 2..32 (trajectory) and 2..64 (fixed) px")
        g = self.gyro_noise_dps_rthz
        if g is not None and not (math.isfinite(g) and 0.0 <= g <= GYRO_NOISE_MAX_DPS_RTHZ):
            raise ConfigError(f"--gyro-noise-dps-rthz must be in [0, {GYRO_NOISE_MAX_DPS_RTHZ:g}] °/s/√Hz "
                              f"(a MEMS gyro: ~0.01), got {g!r}")


def _profile(cfg: Paper000Config):
    from ...mocks import trajectory

    profile, n = trajectory.paper000(cfg.scenario)
    if cfg.max_rate_dps is not None:
        if cfg.scenario != "sim1":
            raise ConfigError("--max-rate-dps applies to the sim1 ramp only")
        profile = trajectory.Ramp((0.0, 0.0, 0.0), (cfg.max_rate_dps * DEG, 0.0, 0.0), 0.0,
                                  (n - 1) / trajectory.PAPER000_RATE_HZ, n / trajectory.PAPER000_RATE_HZ)
    return profile, n


def _interval_rates(qs: np.ndarray, dt: float) -> np.ndarray:
    """Constant body rates (m, 3) that carry qs[i] exactly to qs[i+1] in dt (rad/s)."""
    out = np.empty((qs.shape[0] - 1, 3))
    for i in range(out.shape[0]):
        dq = quat_mult(qs[i + 1], quat_conj(qs[i]))
        if dq[3] < 0:
            dq = -dq
        n = np.linalg.norm(dq[:3])
        ang = 2.0 * math.atan2(n, dq[3])
        out[i] = dq[:3] / n * ang / dt if n > 0 else 0.0
    return out


def _gyro(profile, n_samples: int, cfg: Paper000Config):
    """Measured rates (n, 3) rad/s from the simulator's gyro model, its true drift (3,) and
    its white-noise density (°/s/√Hz)."""
    from ...mocks import gyro_truth

    over = {"odr_hz": cfg.gyro_hz}
    if cfg.gyro_noise_dps_rthz is not None:
        over["noise_density_dps_rthz"] = cfg.gyro_noise_dps_rthz
    params = gyro_truth.gyro_params(cfg.gyro, **over)
    g = gyro_truth.simulate_gyro(profile, (n_samples + 0.5) / cfg.gyro_hz, params, seed=cfg.seed + 7919)
    meas = np.ascontiguousarray(g.omega_meas[:n_samples])
    drift = g.bias[n_samples - 1].copy()
    return meas, drift, params.noise_density_dps_rthz


def _project(q, s, f, cx, cy):
    b = quat_to_dcm(q) @ s
    return np.array([cx + f * b[0] / b[2], cy + f * b[1] / b[2]])


def _plan_stars(qs_frames, f, cx, cy, cfg, mean_rates):
    """Star vectors (ICRS) and, per frame, which star is tracked (hand over near the edge)."""
    def direction(xy, q):
        v = np.array([xy[0], xy[1], f])
        return quat_to_dcm(q).T @ (v / np.linalg.norm(v))

    stars = [direction(cfg.start_xy_px, qs_frames[0])]
    which = np.zeros(len(qs_frames), dtype=np.int64)
    for k in range(len(qs_frames)):
        uv = _project(qs_frames[k], stars[-1], f, cx, cy) - (cx, cy)
        w = mean_rates[k]
        vel = np.array([w[2] * uv[1] - w[1] * f, -w[2] * uv[0] + w[0] * f])
        if np.hypot(*uv) > cfg.edge_px and vel @ uv > 0:
            d = vel / np.linalg.norm(vel)
            stars.append(direction(-d * (cfg.edge_px - 40.0), qs_frames[k]))
        which[k] = len(stars) - 1
    return np.array(stars), which


def run_paper000(cfg: Paper000Config, progress=None) -> dict:
    """Run one scenario; returns per-frame arrays and the summary figures (see module doc)."""
    cfg.validate()
    from ...catalog import StarCatalog
    from ...mocks import trajectory
    from ...mocks.sky import Sky

    rng = np.random.default_rng(cfg.seed)
    from ...mocks.sim_preset import load_preset

    preset = load_preset("xing2012")
    cam = preset.camera
    f, cx, cy = cam.focal_length_px, cam.cx_px, cam.cy_px
    W, H = cam.width_px, cam.height_px
    t_exp = preset.detector.exposure_s
    frame_dt = 1.0 / trajectory.PAPER000_RATE_HZ
    spf = int(round(cfg.gyro_hz * frame_dt))  # gyro samples per frame
    if abs(spf / cfg.gyro_hz - frame_dt) > 1e-9 or abs(t_exp - frame_dt) > 1e-9:
        raise ConfigError("the paper-000 runs need an exposure equal to the frame period and an integer "
                          "number of gyro samples per frame")
    half = spf // 2
    dt = 1.0 / cfg.gyro_hz
    profile, n_frames = _profile(cfg)
    q0 = quat_from_boresight(1.2, 0.4, 0.3)
    t = np.arange(n_frames * spf + 1) * dt
    qs = trajectory.integrate(q0, profile, t)
    true_rates = _interval_rates(qs, dt)
    meas, drift, noise_density = _gyro(profile, n_frames * spf, cfg)
    frame_rates = true_rates.reshape(n_frames, spf, 3).mean(axis=1)
    stars, which = _plan_stars(qs[:-1:spf], f, cx, cy, cfg, frame_rates)
    cat = StarCatalog("paper000", np.arange(len(stars), dtype=np.int64), stars,
                      np.full(len(stars), cfg.vmag), 2016.0)
    sky = Sky(cat, preset, seed=cfg.seed)
    e_per_dn = preset.detector.gain_e_per_adu
    model = MODEL_PINHOLE if cfg.model == "pinhole" else MODEL_FIRST_ORDER
    # per-sample white noise giving the density's angle random walk (one-sided N: σ = N·√(fs/2))
    sig_rate = max(noise_density, 1e-4) * DEG * math.sqrt(cfg.gyro_hz / 2.0)
    sig_brw = cfg.bias_rw_dps_rts * DEG
    k_tr, k_fx = cfg.window_k, cfg.fixed_k
    psf_sigma = preset.optics.psf_sigma_px  # the optics' PSF is known (camera calibration)

    err = {m: np.full((n_frames, 2), np.nan) for m in ("fixed_window", "gyro_window", "ekf")}
    lost = {m: np.zeros(n_frames, dtype=bool) for m in err}
    acq = np.zeros(n_frames, dtype=bool)
    bias_est = np.full((n_frames, 3), np.nan)
    win_px = {m: np.zeros(n_frames, dtype=np.int64) for m in err}
    ekf_sigma = np.full((n_frames, 2), np.nan)
    nis_log = np.full(n_frames, np.nan)
    pred_err = np.full((n_frames, 2), np.nan)  # EKF output at the end of each frame − truth
    meas_err = np.full((n_frames, 2), np.nan)  # C's centroid (the EKF's measurement) − truth
    meas_sig = np.full((n_frames, 2), np.nan)  # its predicted σ
    X = P = None
    a_uv = b_uv = None
    bg = bg_sig = np.nan
    rejects = 0
    n_resets = 0
    acquiring = False
    coast = 0
    accepted = False
    acq_failures = 0
    for k in range(n_frames):
        j0 = k * spf
        exp = sky.expose(qs[j0], quats=qs[j0:j0 + spf + 1])
        sid = int(np.flatnonzero(exp.truth.ids == which[k])[0])
        truth_uv = exp.truth.uv[sid]
        truth_mid = _project(exp.truth.q_mid, stars[which[k]], f, cx, cy)
        if k == 0 or which[k] != which[k - 1] or acquiring:
            acq[k] = True
            # acquisition: squares of 2k px along the path predicted from the catalog position
            # at exposure start (attitude known to ~0.5 px) and the frame's gyro rates
            p0 = _project(qs[j0], stars[which[k]], f, cx, cy) + rng.normal(0.0, 0.5, 2) - (cx, cy)
            nsub = substeps_for(meas[j0:j0 + spf], dt, f, 0.5)
            traj = predict_trajectory(p0[0], p0[1], meas[j0:j0 + spf], dt, np.zeros(3), f, MODEL_PINHOLE, nsub)
            traj[:, 0] += cx
            traj[:, 1] += cy
            spans = trajectory_window(traj, 2 * k_tr, H, W, 0)
            pix = sky.readout_windows(exp, spans, k).astype(np.float64)
            m, sd, cnt = background_far(spans, pix, traj, 4.0)
            if k == 0 or cnt >= 8:
                bg, bg_sig = m, sd
            thr = bg + cfg.threshold_sigma * bg_sig
            pix = suppress_isolated(spans, pix, bg, thr, cfg.isolated_neighbours, cfg.spike_ratio)
            # the smeared-spot fit from the predicted path; a thresholded CoG if it fails
            mid = traj.mean(axis=0)
            u, v, flux, vu, vv, _ = smear_fit(spans, pix, bg, mid[0], mid[1], np.ascontiguousarray(traj - mid),
                                              psf_sigma, bg_sig * bg_sig, e_per_dn, 10, 1e-3)
            if not (np.isfinite(u) and flux > 0 and max(vu, vv) < 0.25):
                u, v, _, npix = cog(spans, pix, bg, thr)
            acquiring = not np.isfinite(u)
            if acquiring:  # not found: keep dead-reckoning and try again next frame
                acq_failures += 1
                if X is not None:
                    spot_ekf_propagate(X, P, meas[j0:j0 + spf], dt, f, sig_rate, sig_brw, model)
                    bias_est[k] = X[2:]
                if progress:
                    progress()
                continue
            a_uv = np.array([u, v])
            b_uv = a_uv.copy()
            if X is None:
                X, P = spot_ekf_init(u - cx, v - cy, np.zeros(3), 0.5, 0.05 * DEG)
            else:
                spot_ekf_reset(X, P, u - cx, v - cy, 0.25, 0.25)
            # bring the EKF from mid-exposure to the end of this frame
            spot_ekf_propagate(X, P, meas[j0 + half:j0 + spf], dt, f, sig_rate, sig_brw, model)
            bias_est[k] = X[2:]
            if progress:
                progress()
            continue
        g_frame = meas[j0:j0 + spf]
        # (C) EKF: trajectory over the exposure from the estimate at exposure start
        nsub = substeps_for(g_frame, dt, f, 0.5)
        traj_c = predict_trajectory(X[0], X[1], g_frame, dt, X[2:].copy(), f, model, nsub)
        traj_c[:, 0] += cx
        traj_c[:, 1] += cy
        spans_c = trajectory_window(traj_c, k_tr, H, W, 2)
        # (B) from B's last centroid (mid of the previous exposure) with raw rates
        g_b = meas[j0 - spf + half:j0 + spf]
        nsub_b = substeps_for(g_b, dt, f, 0.5)
        traj_b = predict_trajectory(b_uv[0] - cx, b_uv[1] - cy, g_b, dt, np.zeros(3), f, MODEL_FIRST_ORDER,
                                    nsub_b)[(spf - half) * nsub_b:]
        traj_b[:, 0] += cx
        traj_b[:, 1] += cy
        spans_b = trajectory_window(traj_b, k_tr, H, W, 1)
        # (A) fixed square on A's last centroid
        spans_a = fixed_window(a_uv[0], a_uv[1], k_fx, H, W, 0)
        spans = concat_windows([spans_a, spans_b, spans_c])
        pix = sky.readout_windows(exp, spans, k).astype(np.float64)
        off = 0
        parts = {}
        for wid, name in ((0, "fixed_window"), (1, "gyro_window"), (2, "ekf")):
            sel = spans[:, 0] == wid
            s = np.ascontiguousarray(spans[sel])
            npx = int(np.sum(s[:, 3] - s[:, 2]))
            parts[name] = (s, pix[off:off + npx])
            off += npx
            win_px[name][k] = npx
        # background: pixels of the gyro windows far from the predicted path, slowly averaged
        for name, traj in (("gyro_window", traj_b), ("ekf", traj_c)):
            s, p = parts[name]
            m, sd, cnt = background_far(s, p, traj, 3.5)
            if cnt >= 8:
                bg = 0.95 * bg + 0.05 * m
                bg_sig = 0.95 * bg_sig + 0.05 * sd
        thr = bg + cfg.threshold_sigma * bg_sig
        if cfg.isolated_neighbours > 0 or cfg.spike_ratio > 0:
            for name in parts:
                s, p = parts[name]
                parts[name] = (s, suppress_isolated(s, p, bg, thr, cfg.isolated_neighbours, cfg.spike_ratio))
        # (A)
        s, p = parts["fixed_window"]
        u, v, _, npix = cog(s, p, bg, thr)
        if npix > 0:
            a_uv = np.array([u, v])
            err["fixed_window"][k] = a_uv - truth_uv
        lost["fixed_window"][k] = npix == 0 or np.hypot(*(a_uv - truth_uv)) > cfg.lost_px
        # (B)
        s, p = parts["gyro_window"]
        u, v, _, npix = cog(s, p, bg, thr)
        if npix > 0:
            b_uv = np.array([u, v])
            err["gyro_window"][k] = b_uv - truth_uv
        else:  # dead-reckon the last centroid to this exposure's mid-point
            b_uv = traj_b[len(traj_b) // 2].copy()
        lost["gyro_window"][k] = npix == 0 or np.hypot(*(b_uv - truth_uv)) > cfg.lost_px
        # (C): propagate to mid-exposure, update there, re-propagate to the frame end
        spot_ekf_propagate(X, P, g_frame[:half], dt, f, sig_rate, sig_brw, model)
        s, p = parts["ekf"]
        mean_xy = traj_c.mean(axis=0)
        if cfg.centroid == "iwcog":
            offsets = np.ascontiguousarray(traj_c[::cfg.offset_stride] - mean_xy)
            u, v, flux, _ = iwcog(s, p, bg, mean_xy[0], mean_xy[1], offsets, cfg.iwcog_sigma_px, 30, 1e-4)
            ok = np.isfinite(u) and flux > cfg.threshold_sigma * bg_sig
            if ok:
                vu, vv = iwcog_variance(s, p, bg, u, v, offsets, cfg.iwcog_sigma_px, bg_sig, e_per_dn)
        elif cfg.centroid == "fit":
            offsets = np.ascontiguousarray(traj_c[::cfg.offset_stride] - mean_xy)
            u, v, flux, vu, vv, _ = smear_fit(s, p, bg, mean_xy[0], mean_xy[1], offsets, psf_sigma,
                                              bg_sig * bg_sig, e_per_dn, 10, 1e-3)
            ok = np.isfinite(u) and flux > 0.0 and np.isfinite(vu) and np.isfinite(vv)
        else:
            u, v, flux, npix = cog(s, p, bg, thr)
            ok = npix > 0
            if ok:
                vu, vv = centroid_variance(s, p, bg, thr, u, v, bg_sig, e_per_dn)
        if ok:
            meas_err[k] = (u - truth_uv[0], v - truth_uv[1])
            meas_sig[k] = (math.sqrt(vu), math.sqrt(vv))
            accepted, nis = spot_ekf_update(X, P, u - cx, v - cy, vu, vv, CHI2_2DOF_999)
            nis_log[k] = nis
            if accepted:
                rejects = 0
                coast = 0
            else:
                rejects += 1
                if rejects >= 3:  # persistent disagreement: trust the image, keep the drift
                    spot_ekf_reset(X, P, u - cx, v - cy, vu, vv)
                    n_resets += 1
                    rejects = 0
                    coast = 0
        if not ok or not accepted:
            coast += 1
            if coast >= cfg.max_coast_frames:  # nothing usable in the EKF's window: re-acquire
                acquiring = True
                coast = 0
        est = X[:2] + (cx, cy)
        err["ekf"][k] = est - truth_mid
        ekf_sigma[k] = np.sqrt([P[0, 0], P[1, 1]])
        lost["ekf"][k] = np.hypot(*(est - truth_mid)) > cfg.lost_px
        spot_ekf_propagate(X, P, g_frame[half:], dt, f, sig_rate, sig_brw, model)
        # the 400 Hz output just before the next image (7.5 ms of gyro-only prediction)
        pred_err[k] = X[:2] + (cx, cy) - _project(qs[j0 + spf], stars[which[k]], f, cx, cy)
        bias_est[k] = X[2:]
        if progress:
            progress()
    return _summarise(cfg, preset, err, lost, acq, bias_est, drift, frame_rates, win_px, ekf_sigma, nis_log,
                      n_resets, meas, true_rates, spf, meas_err, meas_sig, acq_failures, pred_err)


def _summarise(cfg, preset, err, lost, acq, bias_est, drift, frame_rates, win_px, ekf_sigma, nis_log,
               n_resets, meas, true_rates, spf, meas_err, meas_sig, acq_failures, pred_err) -> dict:
    rate_dps = np.linalg.norm(frame_rates, axis=1) / DEG
    use = ~acq
    rms, rms_axes, lost_frac, max_rate = {}, {}, {}, {}
    for m, e in err.items():
        ok = use & ~lost[m] & np.isfinite(e[:, 0])
        ea = e[ok]
        rms_axes[m] = np.sqrt(np.mean(ea ** 2, axis=0)) if len(ea) else np.array([np.nan, np.nan])
        rms[m] = float(np.sqrt(np.mean(ea ** 2))) if len(ea) else float("nan")
        lost_frac[m] = float(np.mean(lost[m][use]))
        bad = np.flatnonzero(use & lost[m])
        max_rate[m] = float(rate_dps[use].max()) if len(bad) == 0 else float(
            rate_dps[use & (rate_dps < rate_dps[bad].min())].max(initial=0.0))
    berr = (bias_est - drift) / DEG
    rel = np.abs(berr[:, :2]) / np.maximum(np.abs(drift[:2] / DEG), 1e-12)
    within = np.all(rel <= 0.1, axis=1)
    conv_s = float("nan")
    idx = np.flatnonzero(~within)
    if within[-1]:
        conv_s = float((idx[-1] + 1) / 100.0) if len(idx) else 0.0
    n_e = float(preset.star_electrons(cfg.vmag))
    det = preset.detector
    bg_e = preset.sky_electrons_per_px() + det.dark_current_e_s * det.exposure_s
    crlb = mortensen_crlb_px(n_e, preset.optics.psf_sigma_px, 1.0, bg_e, det.read_noise_e)
    return {
        "scenario": cfg.scenario,
        "frames": int(len(rate_dps)),
        "max_rate_dps_profile": float(rate_dps.max()),
        "rms_px": rms,
        "rms_px_axes": {m: [float(x) for x in v] for m, v in rms_axes.items()},
        "lost_fraction": {m: lost_frac[m] for m in ("fixed_window", "gyro_window")},
        "lost_fraction_ekf": lost_frac["ekf"],
        "max_rate_tracked_dps": max_rate,
        "bias_error_dps": [float(x) for x in berr[-1]],
        "bias_true_dps": [float(x) for x in drift / DEG],
        "bias_xy_within_10pct_after_s": conv_s,
        "crlb_px": float(crlb),
        "ekf_to_crlb": float(rms["ekf"] / crlb),
        "ekf_gyro_rate_output_rms_px": [float(x) for x in np.sqrt(np.nanmean(
            pred_err[use & ~lost["ekf"]] ** 2, axis=0))],
        "ekf_measurement_rms_px": [float(x) for x in np.sqrt(np.nanmean(meas_err[use] ** 2, axis=0))],
        "ekf_measurement_sigma_px": [float(x) for x in np.sqrt(np.nanmean(meas_sig[use] ** 2, axis=0))],
        "mean_window_px": {m: float(np.mean(v[use])) for m, v in win_px.items()},
        "ekf_resets": int(n_resets),
        "acquisitions": int(acq.sum() - acq_failures),
        "acquisition_failures": int(acq_failures),
        "settings": dataclasses.asdict(cfg),
        "_series": {"err": err, "lost": lost, "acq": acq, "bias_est": bias_est, "drift": drift,
                    "rate_dps": frame_rates / DEG, "ekf_sigma": ekf_sigma, "nis": nis_log,
                    "meas_dps": meas / DEG, "spf": spf},
    }
