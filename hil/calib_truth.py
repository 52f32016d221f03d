"""A calibration file against the simulator truth of a logged run (``gyrostar replay LOG
--compare-calibration CAL.toml``): how far the calibration chain landed from the devices the
simulator really had.

Truth is rebuilt from the log's META (scenario [truth], gyro error set and seed):

* camera — :func:`gyrostar.hil.flatsat.true_camera` of the nominal preset;
* gyro — the emulated gyro senses ``ω_g = S Rᵀ ω_camera + b`` (``S`` the drawn scale and
  misalignment, ``R`` the true mounting), so the map a calibration should find is
  ``M = R S⁻¹``. The gyro's own misalignment has a rotation part that no slew can tell from
  the mounting, so the rotation is compared with the rotation factor of ``M`` (polar
  decomposition) as well as with the mounting alone;
* time offset — the scenario's offset minus the gyro's low-pass group delay
  (:func:`gyrostar.hil.calibrate.gyro_sim.filter_delay_s`): the emulated gyro reports, for a
  sample it takes at time t, the filtered rate at exactly t (:class:`gyrostar.mocks.fake_rates.StreamRates`).
  When the log's folder holds the ``calib.npz`` export, the shift that best explains its raw
  gyro samples by the true body rate is reported beside it (``time_offset_measured_ms``): a
  check whose scatter (about ±1–3 ms on the ``miscal`` slews, from the gyro's noise) is far
  larger than the tolerance, so it is not the truth.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

ARCSEC = np.pi / 180.0 / 3600.0


def measured_time_offset(truth, npz_path, span_s: float = 0.015, step_s: float = 2.5e-4) -> float | None:
    """The gyro's real camera-minus-stamp offset (s): the shift that best explains the raw gyro
    samples of a ``--export calib`` file by the true body rate through a free linear map
    (scale, misalignment, mounting, bias), refined by a parabola through the best three."""
    if truth is None or not len(truth):
        return None
    with np.load(npz_path) as z:
        t, w = z["t"], z["rate"]
    shifts = np.arange(-span_s, span_s + step_s / 2, step_s)
    cost = []
    for dt in shifts:
        sel = (t + dt > truth["t"][0] + 0.5) & (t + dt < truth["t"][-1] - 0.5)
        wt = np.column_stack([np.interp(t[sel] + dt, truth["t"], truth["omega"][:, k]) for k in range(3)])
        x = np.column_stack([wt, np.ones(len(wt))])
        coef, *_ = np.linalg.lstsq(x, w[sel], rcond=None)
        cost.append(float(np.mean((w[sel] - x @ coef) ** 2)))
    i = int(np.clip(np.argmin(cost), 1, len(cost) - 2))
    a, b, c = cost[i - 1], cost[i], cost[i + 1]
    den = a - 2 * b + c
    return float(shifts[i] + (0.5 * step_s * (a - c) / den if den > 0 else 0.0))


def _polar_rotation(m: np.ndarray) -> np.ndarray:
    u, _, vt = np.linalg.svd(m)
    return u @ np.diag([1.0, 1.0, np.linalg.det(u @ vt)]) @ vt


def _angle(a: np.ndarray, b: np.ndarray) -> float:
    c = (np.trace(a @ b.T) - 1.0) / 2.0
    return float(np.arccos(np.clip(c, -1.0, 1.0)))


def compare(log_path, cal_path) -> dict:
    from .. import config as gconfig
    from ..calibration import calfile
    from ..camera import camera_preset
    from . import config as hc
    from .calibrate.gyro_sim import filter_delay_s
    from .flatsat import simulated_gyro, true_camera, true_mounting
    from .replay import load_log

    meta = load_log(log_path, keep_records=False)["meta"]
    cfg = gconfig.from_dict(meta["config"], hc.FlatsatConfig, source="log META")
    scen = gconfig.from_dict(meta["scenario"], hc.Scenario, source="log META")
    if not cfg.simulated:
        from ..errors import NotAvailableError

        raise NotAvailableError(f"{log_path} is from a flatsat with real devices: no simulator truth to compare with")
    cal = calfile.load(cal_path)
    res: dict = {"log": str(log_path), "calibration": str(cal_path), "scenario": scen.name}
    cam_t = true_camera(camera_preset(scen.preset or cfg.sim.preset), scen.truth)
    if cal.camera is not None:
        c = cal.camera
        res["camera"] = {
            "focal_length_px": c.focal_length_px, "focal_length_true_px": cam_t.focal_length_px,
            "focal_length_rel_error_percent": 100.0 * (c.focal_length_px / cam_t.focal_length_px - 1.0),
            "principal_point_px": list(c.principal_point_px),
            "principal_point_true_px": [cam_t.cx_px, cam_t.cy_px],
            "principal_point_error_px": float(np.hypot(c.principal_point_px[0] - cam_t.cx_px,
                                                       c.principal_point_px[1] - cam_t.cy_px)),
            "k1": c.k1, "k1_true": cam_t.k1}
    r_mount = true_mounting(scen.truth)
    g = simulated_gyro(cfg, scen, int(meta["seed"]))
    gp = g.params
    sens = np.diag(1.0 + g.scale) @ g.misalignment
    m_true = r_mount @ np.linalg.inv(sens)
    dt_true = scen.truth.gyro_time_offset_ms * 1e-3 - filter_delay_s(gp)
    m_cal, b_cal, dt_cal = calfile.gyro_to_camera(cal)
    npz = Path(log_path).with_name("calib.npz")
    measured = measured_time_offset(load_log(log_path, keep_records=False)["truth"], npz) if npz.exists() else None
    res["gyro"] = {"map_max_error_ppm": float(np.abs(m_cal - m_true).max() * 1e6),
                   "time_offset_ms": dt_cal * 1e3, "time_offset_true_ms": dt_true * 1e3,
                   "time_offset_error_ms": (dt_cal - dt_true) * 1e3,
                   "time_offset_truth": "model: scenario offset − the gyro filter's group delay",
                   "time_offset_measured_ms": measured * 1e3 if measured is not None else None,
                   "filter_delay_ms": filter_delay_s(gp) * 1e3}
    if cal.alignment is not None:
        from ..attitude import quat_to_dcm

        r_cal = quat_to_dcm(np.asarray(cal.alignment.q_gyro_to_camera, float))
        res["gyro"]["rotation_error_arcsec"] = _angle(r_cal, _polar_rotation(m_true)) / ARCSEC
        res["gyro"]["rotation_vs_mounting_only_arcsec"] = _angle(r_cal, r_mount) / ARCSEC
        res["gyro"]["full_map_rotation_error_arcsec"] = _angle(_polar_rotation(m_cal), _polar_rotation(m_true)) / ARCSEC
    return res


def _f(v, spec: str) -> str:
    return "—" if v is None else format(v, spec)


def text(res: dict) -> str:
    """The comparison for a reader (``--json`` gives the same figures as one object)."""
    lines = [f"calibration {res['calibration']} against the simulator truth of {res['log']} "
             f"(scenario {res['scenario']})"]
    c = res.get("camera")
    if c is not None:
        (cx, cy), (tx, ty) = c["principal_point_px"], c["principal_point_true_px"]
        lines += [f"  camera  focal length {c['focal_length_px']:.2f} px (true {c['focal_length_true_px']:.2f}, "
                  f"{c['focal_length_rel_error_percent']:+.4f} %)",
                  f"          principal point ({cx:.2f}, {cy:.2f}) px (true ({tx:.2f}, {ty:.2f}), "
                  f"{c['principal_point_error_px']:.2f} px off)   k1 {c['k1']:.4g} (true {c['k1_true']:.4g})"]
    else:
        lines.append("  camera  no [camera] table")
    g = res["gyro"]
    lines += [f"  gyro    map to camera: worst element {g['map_max_error_ppm']:.0f} ppm from the truth",
              f"          time offset {g['time_offset_ms']:.3f} ms (true {g['time_offset_true_ms']:.3f} ms: "
              f"{g['time_offset_error_ms']:+.3f} ms off; measured from the raw samples "
              f"{_f(g['time_offset_measured_ms'], '.3f')} ms; gyro filter delay {g['filter_delay_ms']:.3f} ms)"]
    if "rotation_error_arcsec" in g:
        lines.append(f"          rotation {g['rotation_error_arcsec']:.1f}″ from the truth's rotation factor "
                     f"({g['rotation_vs_mounting_only_arcsec']:.1f}″ from the mounting alone; whole map "
                     f"{g['full_map_rotation_error_arcsec']:.1f}″)")
    return "\n".join(lines)
