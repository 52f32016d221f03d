"""Star counts in a square field: hand-placed stars, roll, and the CLI's JSON."""

import json
import math
import os
import subprocess
import sys

import numpy as np
import pytest
from gyrostar.attitude import quat_from_boresight
from gyrostar.mocks.field_count import count_in_square, star_count_distribution


def _vec(x_deg, y_deg):
    v = np.array([math.tan(math.radians(x_deg)), math.tan(math.radians(y_deg)), 1.0])
    return v / np.linalg.norm(v)


def test_square_field_membership_and_roll():
    # boresight at +z of ICRS: quat_from_boresight(0, pi/2, 0); use body-frame offsets directly
    q = np.array([[0.0, 0.0, 0.0, 1.0]])
    stars = np.array([_vec(0, 0), _vec(1.9, 1.9), _vec(2.1, 0), _vec(0, -1.99), _vec(1.5, 1.5)])
    assert count_in_square(stars, q, math.tan(math.radians(2.0)))[0] == 4
    # rolled by 45 deg the corner star (1.9, 1.9) deg leaves the square
    rolled = quat_from_boresight(0.0, 0.0, math.radians(45.0))
    base = quat_from_boresight(0.0, 0.0, 0.0)
    from gyrostar.attitude import quat_to_dcm
    a0 = quat_to_dcm(base)
    stars_icrs = stars @ a0  # body offsets defined at roll 0
    n0 = count_in_square(stars_icrs, base[None, :], math.tan(math.radians(2.0)))[0]
    n45 = count_in_square(stars_icrs, rolled[None, :], math.tan(math.radians(2.0)))[0]
    assert n0 == 4 and n45 == 3


def test_distribution_uniform_sky_matches_poisson():
    # 40,000 uniform stars: mean count in a 4x4 deg field = 40000 * 16 / 41253 = 15.5
    rng = np.random.default_rng(3)
    v = rng.standard_normal((40000, 3))
    v /= np.linalg.norm(v, axis=1)[:, None]
    res = star_count_distribution(v, 4.0, 2000, seed=1)
    d = res["distribution"]
    solid = (4 * math.asin(math.sin(math.radians(2)) ** 2)) * (180 / math.pi) ** 2  # exact square, deg^2
    expect = 40000 * solid / 41252.96
    assert d["mean"] == pytest.approx(expect, rel=0.02)
    assert sum(d[k] for k in ("0", "1", "2", "3", "4", "5", "6", ">6")) == pytest.approx(100.0)


def test_cli_json_keys(tmp_path):
    out = subprocess.run([sys.executable, "-m", "gyrostar", "eval", "starcount", "--fov-deg", "4", "--mag-limit",
                          "7.5", "--trials", "300", "--seed", "2", "--json"], capture_output=True, text=True,
                         env={"GYROSTAR_CACHE": str(tmp_path), "PATH": "/usr/bin:/bin",
                              "NUMBA_CACHE_DIR": os.environ["NUMBA_CACHE_DIR"]},   # the kernels this session compiled
                         timeout=200)
    assert out.returncode == 0, out.stderr
    res = json.loads(out.stdout)
    for k in ("0", "1", "2", "3", "4", "5", "6", ">6", "mean"):
        assert k in res
    assert 7.0 < res["mean"] < 13.0  # ~25,600 stars V <= 7.5 -> ~9.9 per 16 deg^2
    assert res["paper001_table1"][">6"] == 69.96
