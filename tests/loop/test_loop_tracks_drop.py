"""Star tracks leave at the sensor's edge (2 px margin) and, while tracking, after more than
``max_misses`` images missed in a row."""

import math

from gyrostar.attitude import quat_from_boresight
from gyrostar.camera import camera_preset
from gyrostar.loop.coupled import LoopParams
from gyrostar.loop.tracks import StarTracks
from gyrostar.starid.index import load_index


def test_tracks_leave_at_the_edge_and_after_too_many_misses():
    cam = camera_preset("xing2012")
    idx = load_index("hip2", 6.5, max_sep_deg=12.2)
    p = LoopParams(max_stars=16)
    tr = StarTracks(p, cam, idx)
    tr.fill_from_catalog(quat_from_boresight(math.radians(83.8), math.radians(-5.4), 0.0))
    slots = [int(s) for s in tr.tracked()]
    assert len(slots) == 16
    a, b, c, d, e = slots[:5]
    tr.uv[a] = (1.9, 500.0)                                # left of the 2 px margin
    tr.uv[b] = (500.0, cam.height_px - 2.9)                # below it
    tr.uv[c] = (2.0, cam.height_px - 3.0)                  # on it: stays
    tr.misses[d] = p.max_misses + 1
    tr.misses[e] = p.max_misses                            # not more than allowed: stays
    tr.drop_lost(tracking=False)
    assert set(slots) - set(tr.tracked().tolist()) == {a, b}
    tr.drop_lost(tracking=True)
    assert set(slots) - set(tr.tracked().tolist()) == {a, b, d}
