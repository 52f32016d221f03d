"""Image → attitude with no field-of-view hint, against tetra3rs in the same process.

* ``no_hint_tetra3_images_vs_tetra3rs`` — tetra3's 8 public night-sky images
  (``tests/data/tetra3``, 1024×768, 16 bit), each solved many times over: ours is
  :func:`gyrostar.loop.acquire.detect_spots` + :meth:`gyrostar.starid.lost_in_space.LostInSpace.solve`
  (``for_sensor(1024, 768)``, 5–30° range, no hint); the baseline is tetra3rs's
  ``extract_centroids`` + ``solve_from_centroids`` with no hint (its database for 5–30°
  fields, generated once and cached; the estimate it requires given as 17.5° with no limit on
  its error, so it sweeps the whole range). Median wall time per image (``ratio`` = tetra3rs /
  ours: above 1 we are faster) and p99 beside (``p99_ratio``). Both run in this process,
  interleaved image by image, after one untimed warm-up pass each.

Success figures are in the note (a fast wrong answer is no answer).
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def _tetra3rs_db():
    import tetra3rs
    from gyrostar.paths import cache_dir

    path = cache_dir("starid") / f"tetra3rs_{tetra3rs.__version__}_f5-30_auto.bin"
    if path.exists():
        return tetra3rs.SolverDatabase.load_from_file(str(path))
    db = tetra3rs.SolverDatabase.generate_from_gaia(max_fov_deg=30.0, min_fov_deg=5.0)
    db.save_to_file(str(path))
    return db


def _no_hint_images(repeats: int) -> dict:
    try:
        import tetra3rs
        import tifffile
    except ImportError as exc:
        return {"us": None, "baseline_us": None, "ratio": None, "note": f"peer skipped: {exc}"}
    from gyrostar.loop.acquire import detect_spots
    from gyrostar.starid.lost_in_space import LostInSpace

    files = sorted((ROOT / "tests" / "data" / "tetra3").glob("*.tiff"))
    if not files:
        return {"us": None, "baseline_us": None, "ratio": None, "note": "tests/data/tetra3 holds no images"}
    images = [tifffile.imread(f) for f in files]
    lis = LostInSpace.for_sensor(1024, 768, quiet=True).prepare()
    db = _tetra3rs_db()

    def ours(img):
        spots = detect_spots(img.astype(np.float64), 5.0, 150, 7)
        return lis.solve(spots[:, :2])

    def peer(img):
        return db.solve_from_centroids(tetra3rs.extract_centroids(img).centroids, image_shape=img.shape,
                                       fov_estimate_deg=17.5)   # no limit on its error: the 5–30° sweep

    solved = {f.name: (ours(i).solved, bool(peer(i))) for f, i in zip(files, images)}   # warm-up
    t_ours, t_peer = [], []
    for _ in range(repeats):
        for img in images:
            t0 = time.perf_counter()
            ours(img)
            t1 = time.perf_counter()
            peer(img)
            t2 = time.perf_counter()
            t_ours.append(t1 - t0)
            t_peer.append(t2 - t1)
    us, base = float(np.median(t_ours)) * 1e6, float(np.median(t_peer)) * 1e6
    p99, bp99 = float(np.percentile(t_ours, 99)) * 1e6, float(np.percentile(t_peer, 99)) * 1e6
    n_ours = sum(a for a, _ in solved.values())
    n_peer = sum(b for _, b in solved.values())
    return {"us": us, "baseline_us": base, "ratio": base / us, "p99_us": p99, "baseline_p99_us": bp99,
            "p99_ratio": bp99 / p99,
            "note": f"{len(files)} images × {repeats}; ours solves {n_ours}/{len(files)}, tetra3rs "
                    f"{tetra3rs.__version__} {n_peer}/{len(files)}; p99 ours {p99 / 1e3:.1f} ms, "
                    f"tetra3rs {bp99 / 1e3:.1f} ms"}


def run(quick: bool) -> dict:
    return {"no_hint_tetra3_images_vs_tetra3rs": _no_hint_images(3 if quick else 20)}
