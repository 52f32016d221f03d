"""The live view drawn with rerun: one :class:`RerunView` per recording stream.

Entities (time line ``time``: host seconds, the log's clock; see docs/FLATSAT.md):

* ``camera/full_frame`` — a lost-in-space full frame (Image); ``camera/spots`` — the head's spot list;
* ``camera/windows`` — each frame the loop used: its windows' boxes (one entry per frame), and
  ``camera/tiles/w<id>`` — each window's pixels at its sensor position (Image + translation),
  for one frame every :data:`TILE_EVERY_S` (an eye follows no more; 12 images a frame at
  100 Hz would cost the view more CPU than the loop);
* ``camera/centroids`` — the spots measured in those windows (thresholded centre of gravity) with
  their 1σ as ellipses' half-sizes;
* ``camera/stars`` — the identified stars at the update that used the frame (catalog ids, names
  of bright stars), ``camera/trajectories`` — each tracked star's predicted track since the
  frame before;
* ``attitude/q`` (x, y, z, w), ``attitude/rpy_deg`` (3-2-1 Euler angles of ICRS → body, for the
  eye), ``attitude/sigma3_arcsec`` (3σ about body x, y, z from the covariance), one sample per
  output; ``gyro/rate_dps``, ``gyro/bias_dps``; ``loop/stars`` (tracked, identified),
  ``loop/latency_us``, ``loop/overruns``, ``loop/gyro_gaps`` (running counts of flagged outputs);
  ``loop/mode`` — mode changes with the flags that explain them, and run events (TextLog);
* ``link/bytes_per_s`` (down, up) and ``link/utilisation`` (of the link preset's payload rate);
* in simulation: ``truth/q`` at every output and ``truth/error_arcsec`` (x, y, roll) at every
  output with an identified attitude (the log gets the truth when the run ends: so does the view).
"""

from __future__ import annotations

import numpy as np
import rerun as rr

from ...attitude import quat_to_dcm
from ...core.centroid import centroid_variance, cog, window_background
from ...loop.coupled import LoopParams
from ...loop.record import FLAG_ATTITUDE_VALID, FLAG_UPDATE_APPLIED, sigma
from ..analysis import ARCSEC, quat_error_angles_many
from .decode import ViewSink, overruns_and_gaps
from .names import star_label

TIMELINE = "time"
_P = LoopParams()
BATCH_S = 0.1              # outputs are sent to rerun in batches of this much of their time (s)
TILE_EVERY_S = 0.1         # the windows' pixels of one frame per this much time (s): every frame's boxes
_MAX_KEPT = 4_000_000      # outputs kept for the truth comparison at the end (t and q: 40 B each)


def rpy_deg(q: np.ndarray) -> np.ndarray:
    """(n, 3) roll, pitch, yaw in degrees: the 3-2-1 Euler angles of the rotation ICRS → body."""
    a = np.stack([quat_to_dcm(x) for x in q]) if len(q) else np.zeros((0, 3, 3))
    yaw = np.arctan2(a[:, 0, 1], a[:, 0, 0])
    pitch = -np.arcsin(np.clip(a[:, 0, 2], -1.0, 1.0))
    roll = np.arctan2(a[:, 1, 2], a[:, 2, 2])
    return np.degrees(np.stack([roll, pitch, yaw], axis=1))


def _series(rec, path: str, t: np.ndarray, values: np.ndarray) -> None:
    rr.send_columns(path, indexes=[rr.TimeColumn(TIMELINE, duration=t)],
                    columns=rr.Scalars.columns(scalars=np.ascontiguousarray(values, np.float64)), recording=rec)


class RerunView(ViewSink):
    """Draws what :class:`.decode.ViewDecoder` hands it into the recording stream ``rec``."""

    def __init__(self, rec: rr.RecordingStream, link_bytes_per_s: float | None = None,
                 tile_every_s: float = TILE_EVERY_S):
        self.rec = rec
        self.link_bytes_per_s = link_bytes_per_s
        self.width = self.height = 0
        self._tiles: set[int] = set()
        self._overruns = 0
        self._gaps = 0
        self._kept_t: list[np.ndarray] = []
        self._kept_q: list[np.ndarray] = []
        self._kept_n = 0
        self._pending_update: np.ndarray | None = None   # outputs since the last frame (trajectories)
        self._batch: list[np.ndarray] = []
        self._spots_shown = False
        self._tiles_t = -np.inf
        self.tile_every_s = tile_every_s
        self._static()

    def _static(self) -> None:
        log = self.rec.log
        names = {"attitude/q": ["x", "y", "z", "w"], "attitude/rpy_deg": ["roll", "pitch", "yaw"],
                 "attitude/sigma3_arcsec": ["3σ x", "3σ y", "3σ z (roll)"],
                 "gyro/rate_dps": ["x", "y", "z"], "gyro/bias_dps": ["x", "y", "z"],
                 "loop/stars": ["tracked", "identified"], "link/bytes_per_s": ["down", "up"],
                 "truth/q": ["x", "y", "z", "w"], "truth/error_arcsec": ["x", "y", "roll"]}
        for path, n in names.items():
            log(path, rr.SeriesLines(names=n), static=True)

    def _at(self, t: float) -> None:
        self.rec.set_time(TIMELINE, duration=float(t))

    def meta(self, meta: dict) -> None:
        if self.link_bytes_per_s is None:
            try:
                from ...transport.linkrate import preset

                self.link_bytes_per_s = preset(meta["config"]["head"]["link"]).bytes_per_s
            except Exception:     # noqa: BLE001 - a log without a known preset shows bytes/s only
                self.link_bytes_per_s = None

    def sensor(self, width: int, height: int) -> None:
        self.width, self.height = width, height
        self.rec.log("camera", rr.Boxes2D(mins=[[-0.5, -0.5]], sizes=[[width, height]], labels=["sensor"]),
                     static=True)

    def full_frame(self, t: float, image: np.ndarray) -> None:
        self._at(t)
        self.rec.log("camera/full_frame", rr.Image(image))

    def spots(self, t: float, spots: np.ndarray) -> None:
        self._at(t)
        s = np.asarray(spots, np.float64).reshape(-1, 3)
        self.rec.log("camera/spots", rr.Points2D(s[:, :2], radii=3.0, labels=[f"{int(v)}" for v in s[:, 2]]))
        self._spots_shown = True

    def frame(self, t_mid: float, frame: int, spans: np.ndarray, values: np.ndarray) -> None:
        self._at(t_mid)
        ids = np.unique(spans[:, 0])
        show_tiles = t_mid - self._tiles_t >= self.tile_every_s
        if self._spots_shown:          # the lost-in-space spot list is over once frames come
            self.rec.log("camera/spots", rr.Clear(recursive=False))
            self._spots_shown = False
        mins, sizes, cents, halfs = [], [], [], []
        vals = values.astype(np.float64)
        bounds = np.concatenate([[0], np.cumsum(spans[:, 3] - spans[:, 2])])
        for wid in ids:
            rows = np.flatnonzero(spans[:, 0] == wid)
            sp = np.ascontiguousarray(spans[rows])
            v = np.concatenate([vals[bounds[i]:bounds[i + 1]] for i in rows])
            r0, r1 = int(sp[:, 1].min()), int(sp[:, 1].max()) + 1
            c0, c1 = int(sp[:, 2].min()), int(sp[:, 3].max())
            tile = np.zeros((r1 - r0, c1 - c0), np.uint16)
            j = 0
            for s in sp:
                n = s[3] - s[2]
                tile[s[1] - r0, s[2] - c0:s[3] - c0] = v[j:j + n]
                j += n
            if show_tiles:
                self.rec.log(f"camera/tiles/w{int(wid)}", rr.Transform3D(translation=[c0 - 0.5, r0 - 0.5, 0.0]),
                             rr.Image(tile))
            mins.append([c0 - 0.5, r0 - 0.5])
            sizes.append([c1 - c0, r1 - r0])
            bg, noise = window_background(v, 3.0)
            thresh = bg + _P.thresh_sigma * noise
            u, w, _flux, npix = cog(sp, v, bg, thresh)
            if npix > 0:
                var_u, var_v = centroid_variance(sp, v, bg, thresh, u, w, noise, _P.e_per_dn)
                cents.append([u, w])
                halfs.append([np.sqrt(var_u), np.sqrt(var_v)])
        if show_tiles:
            for gone in self._tiles - set(int(i) for i in ids):
                self.rec.log(f"camera/tiles/w{gone}", rr.Clear(recursive=False))
            self._tiles = set(int(i) for i in ids)
            self._tiles_t = t_mid
        self.rec.log("camera/windows", rr.Boxes2D(mins=mins, sizes=sizes, labels=[f"w{int(i)}" for i in ids],
                                                  show_labels=False))
        if cents:
            c = np.array(cents)
            self.rec.log("camera/centroids", rr.Points2D(c, radii=0.6), rr.Ellipses2D(centers=c, half_sizes=halfs))
        else:
            self.rec.log("camera/centroids", rr.Clear(recursive=False))

    def outputs(self, rows: np.ndarray) -> None:
        """Outputs are drawn in batches of :data:`BATCH_S` of their time (fewer, larger rerun calls)."""
        if not len(rows):
            return
        self._batch.append(rows)
        if rows["t"][-1] - self._batch[0]["t"][0] >= BATCH_S:
            self.flush()

    def flush(self) -> None:
        """Draw the outputs batched so far."""
        if not self._batch:
            return
        rows = np.concatenate(self._batch)
        self._batch = []
        t = rows["t"]
        q = rows["q"]
        _series(self.rec, "attitude/q", t, q)
        _series(self.rec, "attitude/rpy_deg", t, rpy_deg(q))
        _series(self.rec, "attitude/sigma3_arcsec", t, 3.0 * sigma(rows["cov"][:, :3, :3]) * ARCSEC)
        _series(self.rec, "gyro/rate_dps", t, np.degrees(rows["omega"]))
        _series(self.rec, "gyro/bias_dps", t, np.degrees(rows["bias"]))
        ident = np.count_nonzero(rows["star_id"] >= 0, axis=1)
        _series(self.rec, "loop/stars", t, np.stack([rows["n_stars"].astype(np.float64), ident], axis=1))
        _series(self.rec, "loop/latency_us", t, rows["latency_us"].astype(np.float64))
        over, gaps = overruns_and_gaps(rows)
        self._overruns += over
        self._gaps += gaps
        _series(self.rec, "loop/overruns", t[-1:], np.array([float(self._overruns)]))
        _series(self.rec, "loop/gyro_gaps", t[-1:], np.array([float(self._gaps)]))
        if self._kept_n + len(rows) <= _MAX_KEPT:
            self._kept_t.append(t.copy())
            self._kept_q.append(np.where((rows["flags"] & FLAG_ATTITUDE_VALID != 0)[:, None], q, np.nan))
            self._kept_n += len(rows)
        self._stars(rows)

    def _stars(self, rows: np.ndarray) -> None:
        """At each output that applied an image update: the identified stars (labels) where
        the loop predicts them, and each one's predicted track since the update before."""
        upd = np.flatnonzero(rows["flags"] & FLAG_UPDATE_APPLIED)
        lo = 0
        for i in upd:
            seg = rows[lo:i + 1]
            prev = self._pending_update
            track = seg if prev is None else np.concatenate([prev, seg])
            lo = i + 1
            self._pending_update = None
            r = rows[i]
            n = int(r["n_stars"])
            ids = r["star_id"][:n]
            px = r["centroid_px"][:n].astype(np.float64)
            self._at(float(r["t"]))
            self.rec.log("camera/stars", rr.Points2D(px, radii=4.0, labels=[star_label(int(s)) for s in ids],
                                                     class_ids=np.clip(ids, 0, None)))
            strips = []
            for sid in ids:
                if sid < 0:
                    continue
                pts = track["centroid_px"][track["star_id"] == sid]     # one slot per output at most
                if len(pts) > 1:
                    strips.append(pts.astype(np.float64))
            self.rec.log("camera/trajectories", rr.LineStrips2D(strips) if strips else rr.Clear(recursive=False))
        rest = rows[lo:]
        if len(rest):
            self._pending_update = rest if self._pending_update is None else \
                np.concatenate([self._pending_update, rest])[-4096:]

    def truth(self, rows: np.ndarray) -> None:
        """The simulator's attitude at each output, and (where the loop had identified its
        attitude) the error against it about body x, y and the roll axis, arcsec."""
        self.flush()
        if not len(rows):
            return
        _series(self.rec, "truth/q", rows["t"], rows["q"])
        if not self._kept_n:
            return
        t = np.concatenate(self._kept_t)
        q = np.concatenate(self._kept_q)
        idx = np.searchsorted(t, rows["t"])
        ok = (idx < len(t)) & (t[np.minimum(idx, len(t) - 1)] == rows["t"])
        ok &= np.isfinite(q[np.minimum(idx, len(t) - 1), 3])       # an identified attitude only
        if np.any(ok):
            err = quat_error_angles_many(q[idx[ok]], rows["q"][ok]) * ARCSEC
            _series(self.rec, "truth/error_arcsec", rows["t"][ok], err)

    def text(self, t: float, text: str, level: str) -> None:
        self._at(t)
        self.rec.log("loop/mode", rr.TextLog(text, level=level))

    def link(self, t: float, down_bytes_per_s: float, up_bytes_per_s: float) -> None:
        self._at(t)
        self.rec.log("link/bytes_per_s", rr.Scalars([down_bytes_per_s, up_bytes_per_s]))
        if self.link_bytes_per_s:
            self.rec.log("link/utilisation", rr.Scalars(max(down_bytes_per_s, up_bytes_per_s) / self.link_bytes_per_s))
