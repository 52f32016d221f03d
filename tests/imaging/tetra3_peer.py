"""The peer's view of tetra3's 8 test images: tetra3rs's database for 10–13° fields (generated
once, cached) and its own centroids and lost-in-space solution of each image."""

from __future__ import annotations

from pathlib import Path

TETRA3 = Path(__file__).resolve().parents[1] / "data" / "tetra3"


def peer_solves():
    """``(db, [(file name, solution, centroids)])`` — tetra3rs's extract_centroids +
    solve_from_centroids of each image (fov estimate 11.5° ± 1.5°)."""
    import tetra3rs
    import tifffile
    from gyrostar.paths import cache_dir

    path = cache_dir("starid") / f"tetra3rs_{tetra3rs.__version__}_f10-13_test.bin"
    if path.exists():
        db = tetra3rs.SolverDatabase.load_from_file(str(path))
    else:
        db = tetra3rs.SolverDatabase.generate_from_gaia(max_fov_deg=13.0, min_fov_deg=10.0)
        db.save_to_file(str(path))
    out = []
    for f in sorted(TETRA3.glob("*.tiff")):
        img = tifffile.imread(f)
        cents = tetra3rs.extract_centroids(img).centroids
        sol = db.solve_from_centroids(cents, image_shape=img.shape, fov_estimate_deg=11.5, fov_max_error_deg=1.5)
        out.append((f.name, sol, cents))
    return db, out
