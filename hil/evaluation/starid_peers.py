"""Optional peer star identifiers, run on the same centroids as ours (evaluation only).

* ``tetra3rs`` — the Rust lost-in-space solver (``pip install tetra3rs``), with a pattern
  database generated from its bundled Gaia catalog for this camera's horizontal field and
  the sensor's limiting magnitude (G ≤ V limit), cached as
  ``cache_dir("starid")/tetra3rs_<version>_f<fov>_m<mag>.bin``. It is given the exact
  pinhole camera (focal length from the field), centroids relative to the principal point
  (+x right, +y down, as ours) with their brightness. Its star ids are Gaia source ids, so
  its answers are scored by attitude (:func:`attitude_correct`).
* ``cedar-solve`` — tetra3 in Python (``pip install --no-deps cedar-solve``) with its
  shipped 10–30° database from Hipparcos; scored by its HIP ids like ours.

:func:`load_peer` returns a peer or the one-line reason it cannot run here. A peer's
``solve(uv, mag, camera)`` returns ``(solved, ids or None, R or None, ms, cpu_ms)``: ``R``
(3, 3) ICRS → camera, ``ms`` the wall time of the solver call and ``cpu_ms`` the CPU time of
the process during it (all its threads: tetra3rs may work outside the calling thread).
"""

from __future__ import annotations

import logging
import math
import time

import numpy as np

from ...paths import cache_dir

PEERS = ("tetra3rs", "cedar-solve")
WRONG_PX = 10.0  # an attitude is right when no star of the field moves more than this


def attitude_correct(r_est: np.ndarray, q_true: np.ndarray, camera) -> bool:
    """Whether rotation ``r_est`` (ICRS → camera) puts every point of the field within
    ``WRONG_PX`` pixels of where the true attitude ``q_true`` (ICRS → body) puts it:
    boresight error × focal length and roll error × half diagonal, each ≤ ``WRONG_PX``."""
    from ...attitude import quat_to_dcm

    d = np.asarray(r_est, dtype=np.float64) @ quat_to_dcm(np.asarray(q_true, dtype=np.float64)).T
    # small-angle error vector of d (rotation from the true camera frame to the estimated one)
    e = 0.5 * np.array([d[2, 1] - d[1, 2], d[0, 2] - d[2, 0], d[1, 0] - d[0, 1]])
    if np.trace(d) < 2.0:  # more than ~60°: plainly wrong
        return False
    half_diag = 0.5 * math.hypot(camera.width_px, camera.height_px)
    return bool(math.hypot(e[0], e[1]) * camera.focal_length_px <= WRONG_PX
                and abs(e[2]) * half_diag <= WRONG_PX)


class Tetra3rsPeer:
    """tetra3rs with a database for ``camera`` (horizontal field) and ``mag_limit``."""

    name = "tetra3rs"
    scored_by = "attitude"

    def __init__(self, camera, mag_limit: float):
        import tetra3rs

        self._t3 = tetra3rs
        fov = float(camera.fov_x_deg)
        path = cache_dir("starid") / f"tetra3rs_{tetra3rs.__version__}_f{fov:.4f}_m{mag_limit:.2f}.bin"
        db = None
        if path.exists():
            try:
                db = tetra3rs.SolverDatabase.load_from_file(str(path))
            except (OSError, ValueError):
                path.unlink(missing_ok=True)
        if db is None:
            db = tetra3rs.SolverDatabase.generate_from_gaia(max_fov_deg=fov, star_max_magnitude=float(mag_limit))
            db.save_to_file(str(path))
        self.db = db
        self.model = tetra3rs.CameraModel.from_fov(fov_deg=fov, image_width=camera.width_px,
                                                   image_height=camera.height_px)
        self.name = f"tetra3rs {tetra3rs.__version__} (database {fov:.2f}°, G ≤ {mag_limit:g})"

    def solve(self, uv: np.ndarray, mag: np.ndarray, camera):
        xy = np.empty((uv.shape[0], 3))
        xy[:, 0] = uv[:, 0] - camera.cx_px
        xy[:, 1] = uv[:, 1] - camera.cy_px
        xy[:, 2] = 10.0 ** (-0.4 * np.asarray(mag, dtype=np.float64))
        t0, c0 = time.perf_counter(), time.process_time()
        sol = self.db.solve_from_centroids(xy, camera_model=self.model)
        ms, cpu = (time.perf_counter() - t0) * 1e3, (time.process_time() - c0) * 1e3
        if not isinstance(sol, self._t3.SolveResult):
            return False, None, None, ms, cpu
        return True, None, np.asarray(sol.rotation_matrix_icrs_to_camera, dtype=np.float64), ms, cpu


class CedarPeer:
    """cedar-solve's Tetra3 with its shipped database (10–30° fields, HIP ids)."""

    name = "cedar-solve (tetra3, default database)"
    scored_by = "ids"

    def __init__(self, t3):
        self.t3 = t3

    def solve(self, uv: np.ndarray, mag: np.ndarray, camera):
        fov = float(camera.fov_x_deg)
        t0, c0 = time.perf_counter(), time.process_time()
        sol = self.t3.solve_from_centroids(np.ascontiguousarray(uv[:, ::-1]), (camera.height_px, camera.width_px),
                                           fov_estimate=fov, fov_max_error=0.1 * fov, return_matches=True)
        ms, cpu = (time.perf_counter() - t0) * 1e3, (time.process_time() - c0) * 1e3
        if sol.get("RA") is None:
            return False, None, None, ms, cpu
        ids = -np.ones(uv.shape[0], dtype=np.int64)
        for (y, x), cat_id in zip(np.asarray(sol["matched_centroids"]).reshape(-1, 2), sol["matched_catID"]):
            k = int(np.argmin(np.hypot(uv[:, 0] - x, uv[:, 1] - y)))
            ids[k] = int(np.ravel(cat_id)[0])
        return True, ids, None, ms, cpu


def _cedar(camera, catalog: str):
    if catalog != "hip2":
        return "cedar-solve's ids are HIP numbers: hip2 runs only"
    if not 10.0 <= camera.fov_x_deg <= 30.0:
        return (f"cedar-solve's shipped database covers 10–30° fields, not {camera.fov_x_deg:.1f}°; "
                "building another needs its hip_main/tyc_main catalog files, not shipped")
    try:
        import tetra3
    except Exception as exc:  # noqa: BLE001 - any import failure is a reason to skip
        return f"cedar-solve not importable: {exc}"
    # cedar-solve 0.5.1 pins numpy<2 and calls np.math.factorial; np.math was numpy's alias
    # of the standard library module, removed in numpy 2 (this environment needs numpy 2)
    if not hasattr(np, "math"):
        np.math = math
    logging.getLogger("tetra3").setLevel(logging.WARNING)
    try:
        t3 = tetra3.Tetra3()
    except Exception as exc:  # noqa: BLE001
        return f"cedar-solve default database not loadable: {exc}"
    logging.getLogger("tetra3.Tetra3").setLevel(logging.WARNING)
    return CedarPeer(t3)


def load_peer(name: str, camera, mag_limit: float, catalog: str = "hip2"):
    """The peer ``name`` set up for ``camera``, or a one-line reason it is unavailable."""
    if name == "cedar-solve":
        return _cedar(camera, catalog)
    if name != "tetra3rs":
        return f"unknown peer {name!r} (known: {', '.join(PEERS)})"
    try:
        import tetra3rs  # noqa: F401
    except Exception as exc:  # noqa: BLE001
        return f"tetra3rs not importable (pip install tetra3rs): {exc}"
    try:
        return Tetra3rsPeer(camera, mag_limit)
    except Exception as exc:  # noqa: BLE001 - database generation failures are a reason to skip
        return f"tetra3rs database not available: {exc}"


def score_peer(peer, solved: bool, ids, r_est, frame, camera) -> tuple[bool, bool]:
    """``(solved, correct)`` of one peer answer against the simulator's truth: by ids (≥ 2
    right, none wrong) when the peer names HIP stars, else by attitude."""
    from ...mocks.star_lists import score

    if not solved:
        return False, False
    if ids is not None:
        c, w = score(ids, frame.truth, frame.alt)
        return True, c >= 2 and w == 0
    return True, attitude_correct(r_est, frame.q, camera)
