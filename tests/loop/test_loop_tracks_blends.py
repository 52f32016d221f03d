"""Star tracks take blended stars (a neighbour shares their spot) only when too few clean
ones are on the sensor: their centroid is not at their catalog place."""

import math

import numpy as np
from gyrostar.attitude import quat_from_boresight
from gyrostar.camera import camera_preset
from gyrostar.loop.coupled import LoopParams
from gyrostar.loop.tracks import BLEND_ADMIT_BELOW, StarTracks
from gyrostar.starid.index import load_index

Q_ORION = quat_from_boresight(math.radians(83.8), math.radians(-5.4), 0.0)   # a full field


def _candidates(cam, idx, q):
    """Index rows attitude ``q`` puts on the sensor, brightest first (an empty tracker's pick)."""
    tr = StarTracks(LoopParams(max_stars=16), cam, idx)
    tr.fill_from_catalog(q)
    return [int(n) for n in tr.nav[tr.tracked()]]


def test_blended_stars_give_way_to_clean_ones():
    cam = camera_preset("xing2012")
    idx = load_index("hip2", 6.5, max_sep_deg=12.2)
    plain = _candidates(cam, idx, Q_ORION)
    assert len(plain) == 16
    mask = np.zeros(len(idx), bool)
    mask[plain[:3]] = True                   # the three brightest are blends
    tr = StarTracks(LoopParams(max_stars=16), cam, idx, mask)
    tr.fill_from_catalog(Q_ORION)
    got = [int(n) for n in tr.nav[tr.tracked()]]
    assert len(got) == 16 and not set(got) & set(plain[:3])
    assert set(plain[3:]) <= set(got)        # the rest are still taken


def test_blended_stars_fill_a_sparse_field_up_to_the_minimum():
    cam = camera_preset("xing2012")
    idx = load_index("hip2", 6.5, max_sep_deg=12.2)
    plain = _candidates(cam, idx, Q_ORION)
    mask = np.ones(len(idx), bool)
    mask[plain[5]] = mask[plain[9]] = False  # two clean stars on the sensor
    tr = StarTracks(LoopParams(max_stars=16), cam, idx, mask)
    tr.fill_from_catalog(Q_ORION)
    got = [int(n) for n in tr.nav[tr.tracked()]]
    assert len(got) == BLEND_ADMIT_BELOW == 4
    assert {plain[5], plain[9]} <= set(got)  # both clean ones, then the two brightest blends
    assert set(got) - {plain[5], plain[9]} == set(plain[:2])
    # a second fill with more free slots takes no further blend
    tr.fill_from_catalog(Q_ORION)
    assert len(tr.tracked()) == 4


def test_blended_stars_leave_when_clean_ones_come_onto_the_sensor():
    """A sparse field lets blends in; as the attitude moves on and clean stars enter the
    sensor, the blends give their slots up."""
    from gyrostar.attitude import quat_mult, rotvec_to_quat

    cam = camera_preset("xing2012")
    idx = load_index("hip2", 6.5, max_sep_deg=12.2)
    first = _candidates(cam, idx, Q_ORION)
    q2 = quat_mult(rotvec_to_quat(np.radians([3.0, 0.0, 0.0])), Q_ORION)      # 3° on
    second = _candidates(cam, idx, q2)
    new = [n for n in second if n not in first]
    assert len(new) >= BLEND_ADMIT_BELOW
    mask = np.ones(len(idx), bool)
    mask[first[5]] = mask[first[9]] = False      # two clean stars in the first field
    mask[new] = False                            # the stars that come into view are clean
    tr = StarTracks(LoopParams(max_stars=16), cam, idx, mask)
    tr.fill_from_catalog(Q_ORION)
    assert sum(mask[n] for n in tr.nav[tr.tracked()]) == 2          # two blends let in
    v = tr.version
    tr.fill_from_catalog(q2)
    got = [int(n) for n in tr.nav[tr.tracked()]]
    assert not any(mask[n] for n in got)                            # the blends are gone
    assert set(new) <= set(got) and tr.version > v


def test_blend_mask_must_cover_the_index():
    import pytest

    cam = camera_preset("xing2012")
    idx = load_index("hip2", 6.5, max_sep_deg=12.2)
    with pytest.raises(ValueError, match="blended mask"):
        StarTracks(LoopParams(), cam, idx, np.zeros(3, bool))
