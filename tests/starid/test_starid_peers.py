"""Peer solvers (optional) and the attitude scoring used for them."""

import math

import numpy as np
import pytest
from gyrostar.attitude import quat_from_boresight, quat_mult, quat_to_dcm, random_attitudes, rotvec_to_quat
from gyrostar.catalog import load_catalog
from gyrostar.hil.evaluation.starid_peers import attitude_correct, load_peer
from gyrostar.mocks.star_lists import Sky, camera_for_fov


def test_attitude_correct_against_hand_made_rotations():
    cam = camera_for_fov(10.0, 1024)            # f = 5852 px, half diagonal 724 px
    q = quat_from_boresight(1.0, 0.4, 0.3)
    r_true = quat_to_dcm(q)
    assert attitude_correct(r_true, q, cam)
    for axis, px, scale, ok in ((0, 5.0, cam.focal_length_px, True), (1, 20.0, cam.focal_length_px, False),
                                (2, 5.0, 724.08, True), (2, 20.0, 724.08, False)):
        rv = np.zeros(3)
        rv[axis] = px / scale
        r_est = quat_to_dcm(quat_mult(rotvec_to_quat(rv), q))
        assert attitude_correct(r_est, q, cam) is ok, (axis, px)
    assert not attitude_correct(quat_to_dcm(quat_from_boresight(2.0, -0.4, 0.3)), q, cam)


def test_unknown_peer_is_a_reason():
    assert "unknown peer" in load_peer("astrometry", camera_for_fov(10.0, 1024), 6.5)


def test_tetra3rs_solves_our_fields():
    pytest.importorskip("tetra3rs", reason="tetra3rs not installed (pip install tetra3rs)")
    cam = camera_for_fov(10.0, 1024)
    peer = load_peer("tetra3rs", cam, 6.5)
    assert not isinstance(peer, str), peer
    sky = Sky(load_catalog("hip2", 7.0))
    rng = np.random.default_rng(2)
    right = 0
    for q in random_attitudes(20, rng):
        f = sky.observe(cam, q, 6.5, 0.5, 0.0, 0, rng)
        solved, ids, r_est, ms, cpu = peer.solve(f.uv, f.mag, cam)
        assert math.isfinite(ms) and ms > 0 and cpu >= 0
        right += solved and attitude_correct(r_est, f.q, cam)
    assert right >= 18
