"""Lost-in-space from the head's own spot list (FIND_SPOTS) in the loop: on a 921.6 kBd UART
the fix comes within a few tenths of a second (a full frame needs 14 s of wire there), and
a head whose firmware lacks FIND_SPOTS is acquired from full frames instead. Truth: the
simulator's attitude, and each preset's line rate."""

import numpy as np
import pytest
from gyrostar.hil import config as hc
from gyrostar.hil.runner import run_flatsat


def _run(tmp_path, link: str, acquire: str, seconds: float):
    cfg = hc.load_flatsat()
    cfg.head.link = link
    cfg.head.acquire = acquire
    folder = tmp_path / f"{link}-{acquire}"
    folder.mkdir()
    outs = []
    res = run_flatsat(cfg, hc.load_scenario("demo"), duration=seconds, seed=3, folder=folder, plots=False,
                      status=False, fast=True, on_output=lambda r: outs.append(r.copy()))
    return res, np.concatenate(outs)


def _first_track_s(res) -> float:
    return next(t0 for t0, _, mode in res["health"]["mode_timeline"] if mode == "TRACK")


def test_spot_list_acquires_over_a_slow_uart(tmp_path):
    res, _ = _run(tmp_path, "uart-921k", "spots", 4.0)
    # exposure + the head's scan + ~5 kB at 92 kB/s, then the confirming image
    assert _first_track_s(res) < 0.5, res["health"]["mode_timeline"]
    assert res["counters"]["acquisitions"] == 1 and res["counters"]["acquisition_failures"] == 0
    assert res["acquisition_image"] == "spots"
    assert res["attitude_error_arcsec_1sigma"] < 3 * res["floor_arcsec"]
    assert res["samples_lost"] == 0


def test_full_frame_acquisition_takes_the_wire_time(tmp_path):
    """The same link with full frames: 1.32 MB at 92.16 kB/s is 14.3 s, so no fix in 4 s."""
    res, _ = _run(tmp_path, "uart-921k", "full_frame", 4.0)
    assert res["mode_seconds"]["TRACK"] == 0.0 and res["counters"]["acquisitions"] == 0


def test_firmware_without_find_spots_falls_back_to_full_frames(tmp_path, monkeypatch):
    from gyrostar.mocks import head_emulator as he
    from gyrostar.protocol.defs import ErrorCode

    def old_firmware(self, q):
        raise he._Reject(ErrorCode.UNKNOWN_TYPE)

    monkeypatch.setattr(he.HeadEmulator, "_find_spots", old_firmware)
    res, _ = _run(tmp_path, "usb-fs", "spots", 4.0)
    # full frames over usb-fs: ~1.5 s each, then TRACK
    assert 1.0 < _first_track_s(res) < 3.5, res["health"]["mode_timeline"]
    assert res["acquisition_image"] == "full_frame"
    assert res["counters"]["acquisition_failures"] == 0


@pytest.mark.parametrize("acquire", ["spots", "nonsense"])
def test_acquire_setting_is_checked(acquire):
    cfg = hc.FlatsatConfig()
    cfg.head.acquire = acquire
    if acquire == "spots":
        cfg.head.validate()
    else:
        with pytest.raises(ValueError, match="head.acquire"):
            cfg.head.validate()
