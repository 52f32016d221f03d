"""``gyrostar replay LOG --export calib --out X.npz``: calibration inputs from a flatsat run.

The log is replayed through the same driver and loop (:func:`gyrostar.hil.flatsat.replay_loop`)
with two taps on public interfaces:

* the gyro device: every sample as the driver read it — gyro axes and gyro time stamps; on
  a calibrated run the tap sits under the :class:`~gyrostar.gyro.calibrated.CalibratedGyro`,
  so the rates are raw;
* the head port: every windows job, the spans submitted and the pixels and exposure
  mid-time that came back.

Each window's spot is measured again independently of the loop's filter (window background
by median/MAD clipping, thresholded centre of gravity: :mod:`gyrostar.core.centroid`) and
given the catalog star the loop was tracking there: the predicted centroid in the output
record nearest to the exposure mid-time that lies within ``GATE_PX`` of the measured one,
with no other prediction within twice that. A blended star (another catalog star within
``NEIGHBOUR_PX`` at most ``BLEND_DMAG`` fainter, :func:`gyrostar.starid.blends.blended`) is
left out: its spot's centre is not its catalog place. Fields (frames) with
≥ 3 labelled stars get a QUEST attitude through the run's camera. Layout of the file:
:mod:`gyrostar.calibration.star_fields`.
"""

from __future__ import annotations

import json
from collections import deque
from pathlib import Path

import numpy as np

GATE_PX = 3.0
THRESH_SIGMA = 5.0
NEIGHBOUR_PX = 5.0       # px: a star with a neighbour this close is a blend for calibration (PSF σ ≈ 0.85 px: at
#                          5 px the overlap e^(−d²/4σ²) < 1e-3; the window's centre of gravity reaches that far)


class GyroTap:
    """A gyro device that also keeps a copy of every sample it appends."""

    def __init__(self, gyro):
        self.gyro = gyro
        self.t: list[np.ndarray] = []
        self.rate: list[np.ndarray] = []

    def read(self, out, event_time=None, event_clock=None):
        n0 = out.n
        n = self.gyro.read(out, event_time, event_clock)
        if n:
            self.t.append(out.t[n0:n0 + n].copy())
            self.rate.append(out.rate[n0:n0 + n].copy())
        return n

    def __getattr__(self, name):
        return getattr(self.gyro, name)


class HeadTap:
    """A head port that pairs every windows job's spans with the result it returned."""

    def __init__(self, head):
        self.head = head
        self.pending: deque = deque()
        self.sets: dict[int, np.ndarray] = {}     # streaming: window set by the frame it names
        self.frames: list[tuple[float, np.ndarray, np.ndarray]] = []

    def submit_windows(self, spans, *stream):
        """Request mode ``(spans)``; streaming ``(spans, frame, post)``: the set is kept under
        the frame it names and paired with the frame that used it (``res.set_frame``)."""
        if stream:
            self.sets[int(stream[0])] = np.array(spans, copy=True)
            for old in [k for k in self.sets if k < int(stream[0]) - 16]:
                del self.sets[old]
            return self.head.submit_windows(spans, *stream)
        self.pending.append(np.array(spans, copy=True))
        return self.head.submit_windows(spans)

    def poll(self):
        res = self.head.poll()
        if res is None or res.kind != "windows":
            return res
        set_frame = getattr(res, "set_frame", None)
        if set_frame is not None:
            spans = self.sets.get(int(set_frame))
        else:
            spans = self.pending.popleft() if self.pending else None
        if spans is not None and res.error is None and res.values is not None:
            self.frames.append((float(res.t_mid), spans, np.array(res.values, copy=True)))
        return res

    def __getattr__(self, name):
        return getattr(self.head, name)


def measure(spans: np.ndarray, values: np.ndarray, omega=None, camera=None, exposure_s: float = 0.0,
            psf_sigma_px: float = 0.85, e_per_dn: float = 5.0) -> np.ndarray:
    """(n, 4) [window_id, u, v, σ] of every window with a spot: thresholded CoG, refined by the
    fit of the PSF smeared along the spot's path over the exposure (from the body rate
    ``omega`` rad/s, camera axes) when given — a CoG is pulled towards the window's centre
    when the window clips the spot, and the windows were placed through the run's camera
    model, the very model being calibrated. σ (px per axis) is the fit's CRLB, the RMS of its
    two axes; NaN for a plain CoG."""
    from ..core.centroid import cog, smear_fit, window_background, window_spans_of

    rows = []
    for wid in np.unique(spans[:, 0]):
        a, e, v0 = window_spans_of(spans, int(wid))
        sp = np.ascontiguousarray(spans[a:e])
        npx = int(np.sum(sp[:, 3] - sp[:, 2]))
        if e <= a or v0 + npx > len(values):
            continue
        wv = np.ascontiguousarray(values[v0:v0 + npx], np.float64)
        bg, noise = window_background(wv, 3.0)
        u, v, flux, npix = cog(sp, wv, bg, bg + THRESH_SIGMA * noise)
        if npix < 3 or not np.isfinite(u):
            continue
        sigma = np.nan
        if omega is not None and camera is not None:
            off = smear_offsets(u, v, omega, camera, exposure_s)
            fu, fv, _, var_u, var_v, _ = smear_fit(sp, wv, bg, u, v, off, psf_sigma_px, noise * noise, e_per_dn,
                                                    20, 1e-4)
            if not (np.isfinite(fu) and np.isfinite(fv) and abs(fu - u) < 2.0 and abs(fv - v) < 2.0):
                continue                   # a spot the model does not describe: not a calibration point
            u, v = fu, fv
            sigma = float(np.sqrt(0.5 * (var_u + var_v)))
        rows.append((wid, u, v, sigma))
    return np.array(rows, float).reshape(-1, 4)


def smear_offsets(u: float, v: float, omega: np.ndarray, camera, exposure_s: float) -> np.ndarray:
    """The spot's path over the exposure relative to its mean (m, 2) px, ≤ 0.4 px apart:
    image-plane velocity ``V_x = ω_z·y − ω_y·f``, ``V_y = −ω_z·x + ω_x·f`` (ARCHITECTURE, frames)."""
    f = camera.focal_length_px
    x, y = u - camera.cx_px, v - camera.cy_px
    vel = np.array([omega[2] * y - omega[1] * f, -omega[2] * x + omega[0] * f])
    m = max(2, int(np.ceil(np.hypot(*vel) * exposure_s / 0.4)) + 1)
    t = (np.arange(m) + 0.5) / m - 0.5
    return np.ascontiguousarray(t[:, None] * exposure_s * vel[None, :])


def identify(uv: np.ndarray, rec) -> np.ndarray:
    """Catalog id of each measured spot from one output record's predicted centroids (−1: none)."""
    n = int(np.count_nonzero(rec["star_id"] >= 0))      # the tracked stars' rows (n_stars: seen, in COAST)
    ids = np.full(len(uv), -1, np.int64)
    if n == 0 or not len(uv):
        return ids
    pred = rec["centroid_px"][:n].astype(np.float64)
    d = np.linalg.norm(uv[:, None, :] - pred[None, :, :], axis=2)
    for i in range(len(uv)):
        j = int(np.argmin(d[i]))
        others = np.delete(d[i], j)
        if d[i, j] <= GATE_PX and (not len(others) or others.min() > 2 * GATE_PX) and int(np.argmin(d[:, j])) == i:
            ids[i] = int(rec["star_id"][j])
    return ids


def export_calib(path: str | Path, out: str | Path) -> dict:
    """Replay ``path`` and write the calibration input ``out`` (.npz); returns the figures."""
    from .. import config as gconfig
    from ..calibration.star_fields import field_attitudes
    from ..catalog import deepest_limit, load_catalog
    from ..loop.sinks import CallbackSink
    from ..starid.blends import BLEND_DMAG, blended
    from . import config as hc
    from . import flatsat
    from .replay import load_log, log_state

    log = load_log(path)
    meta = log["meta"]
    loop, run_all = flatsat.replay_loop(meta, log["records"], [CallbackSink(lambda r: None)])
    dev = loop.gyro
    if hasattr(dev, "raw"):                # CalibratedGyro: tap the raw device under it
        dev.raw = gtap = GyroTap(dev.raw)
    else:
        loop.gyro = gtap = GyroTap(dev)
    loop.head = htap = HeadTap(loop.head)
    steps, stopped = run_all()

    outputs = log["outputs"]
    t_out = outputs["t"]
    cfg = gconfig.from_dict(meta["config"], hc.FlatsatConfig, source="log META")
    limit = cfg.loop.mag_limit           # the labels are the loop's tracked stars (its index stops here)
    cat = load_catalog(cfg.sim.catalog, limit)
    deep = load_catalog(cfg.sim.catalog, deepest_limit(cfg.sim.catalog, limit + BLEND_DMAG))
    blends = blended(cat, deep, NEIGHBOUR_PX / loop.camera.focal_length_px, BLEND_DMAG)
    pos = {int(i): k for k, i in enumerate(cat.ids) if not blends[k]}
    blend_ids = set(cat.ids[blends].tolist())
    n_blended = 0
    fields, uvs, refs, sids, sigmas, t_cam = [], [], [], [], [], []
    t_g = np.concatenate(gtap.t) if gtap.t else np.zeros(0)
    rate = np.concatenate(gtap.rate) if gtap.rate else np.zeros((0, 3))
    exposure_s = cfg.head.exposure_ms * 1e-3
    for t_mid, spans, values in htap.frames:
        # the loop's bias-corrected body rate over the exposure (camera axes)
        omega = np.array([np.interp(t_mid, t_out, outputs["omega"][:, k]) for k in range(3)]) if len(t_out) else None
        spots = measure(spans, values, omega, loop.camera, exposure_s, loop.p.psf_sigma_px, loop.p.e_per_dn)
        if not len(spots) or not len(t_out):
            continue
        k = int(np.clip(np.searchsorted(t_out, t_mid), 1, len(t_out) - 1))
        k = k - 1 if abs(t_out[k - 1] - t_mid) <= abs(t_out[k] - t_mid) else k
        rec = outputs[k]
        if rec["mode"] != 1:          # TRACK only: identities are those of an attitude that holds
            continue
        ids = identify(spots[:, 1:3], rec)
        sel = [i for i in range(len(ids)) if ids[i] >= 0 and int(ids[i]) in pos]
        n_blended += sum(1 for i in ids if int(i) in blend_ids)
        if len(sel) < 3:
            continue
        f = len(t_cam)
        t_cam.append(t_mid)
        for i in sel:
            fields.append(f)
            uvs.append(spots[i, 1:3])
            sigmas.append(spots[i, 3])
            refs.append(cat.vectors[pos[int(ids[i])]])
            sids.append(int(ids[i]))
    field = np.array(fields, np.int64)
    uv = np.array(uvs, float).reshape(-1, 2)
    ref = np.array(refs, float).reshape(-1, 3)
    t_cam = np.array(t_cam, float)
    uv_sigma = np.array(sigmas, float)
    ok, q_cam = field_attitudes(field, uv, ref, loop.camera, len(t_cam), uv_sigma=uv_sigma)
    from ..files import whole_or_nothing

    # written whole to a temporary name, then renamed to exactly ``out``
    with whole_or_nothing(Path(out)) as part, open(part, "wb") as fh:
        np.savez_compressed(fh, t=t_g, rate=rate, field=field, uv=uv, ref=ref, star_id=np.array(sids, np.int64),
                            uv_sigma=uv_sigma,
                            t_cam=t_cam, q_cam=q_cam, camera=loop.camera.as_array(),
                            meta=np.array(json.dumps({"log": str(path),
                                                      "scenario": meta.get("scenario", {}).get("name"),
                                                      "calibration": (meta.get("calibration") or {}).get("sha256")})))
    return {"log": str(path), "export": "calib", "out": str(out), "gyro_samples": int(len(t_g)),
            "window_frames": len(htap.frames), "fields": int(len(t_cam)), "fields_with_attitude": int(ok.sum()),
            "star_observations": int(len(field)), "blended_observations_left_out": n_blended,
            "replay_steps": steps, "stopped": stopped} | log_state(log)
