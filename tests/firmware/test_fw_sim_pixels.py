"""``gyrostar sim pixels FRAME --sensor FILE`` loads a frame into the firmware host's pixel file
(in place, while the host program has it mapped), so ``gyrostar fw spots`` sees it."""

import json
import subprocess
import sys

import numpy as np
import pytest
from gyrostar.fwtools import build

pytest.importorskip("gyrostar.head.client")
from gyrostar.mocks.firmware_host import FirmwareHost  # noqa: E402

STARS = [(30.0, 20.0), (90.3, 61.7), (50.6, 75.2)]        # (column, row) px


def _gyrostar(*args):
    return subprocess.run([sys.executable, "-m", "gyrostar", *map(str, args)], capture_output=True, text=True,
                          timeout=120)


def _frame(w=128, h=96):
    rng = np.random.default_rng(3)
    yy, xx = np.mgrid[0:h, 0:w]
    img = 40.0 + rng.normal(0.0, 2.0, (h, w))
    for u, v in STARS:
        img += 600.0 * np.exp(-((xx - u) ** 2 + (yy - v) ** 2) / (2 * 1.2**2))
    return np.clip(np.round(img), 0, 1023).astype(np.uint16)


def test_loaded_frame_is_what_fw_spots_finds(tmp_path):
    build.build("host")
    np.save(tmp_path / "frame.npy", _frame())
    with FirmwareHost(128, 96, planes=1) as host:
        before = _gyrostar("fw", "spots", host.path, "--json")
        load = _gyrostar("sim", "pixels", tmp_path / "frame.npy", "--sensor", host.pixels.path, "--json")
        after = _gyrostar("fw", "spots", host.path, "--json")
    assert load.returncode == 0, load.stderr
    assert json.loads(load.stdout)["created"] is False
    assert before.returncode == 0 and json.loads(before.stdout)["spots"] == []       # the zero-filled sensor
    assert after.returncode == 0, after.stderr
    found = np.array(json.loads(after.stdout)["centroids_uv_flux"])[:, :2]
    assert len(found) == len(STARS)
    for u, v in STARS:
        assert np.min(np.hypot(found[:, 0] - u, found[:, 1] - v)) < 0.3


def test_new_pixel_file_takes_the_frame_and_bad_frames_are_refused(tmp_path):
    np.save(tmp_path / "frame.npy", _frame())
    res = _gyrostar("sim", "pixels", tmp_path / "frame.npy", "--sensor", tmp_path / "s.gspx", "--planes", "1")
    assert res.returncode == 0, res.stderr
    data = (tmp_path / "s.gspx").read_bytes()
    assert data[:4] == b"GSPX" and len(data) == 64 + 2 * 128 * 96
    np.testing.assert_array_equal(np.frombuffer(data[64:], "<u2").reshape(96, 128), _frame())
    np.save(tmp_path / "small.npy", _frame(64, 48))
    np.save(tmp_path / "hot.npy", _frame().astype(np.int32) * 4)
    for frame, words in (("small.npy", "64×48 pixels, the pixel file"), ("hot.npy", "0 … 1023 (10 bits)")):
        res = _gyrostar("sim", "pixels", tmp_path / frame, "--sensor", tmp_path / "s.gspx")
        lines = res.stderr.strip().splitlines()
        assert res.returncode == 2 and len(lines) == 1 and words in lines[0], res.stderr
