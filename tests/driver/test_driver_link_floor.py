"""`gyrostar bench driver`: each link preset's exposure → output floor, against the hand sum
half exposure + the link's latency + the frame's bytes at its sustained rate + half a gyro
period (10 ms exposures, 400 Hz gyro)."""

import json
import subprocess
import sys
from pathlib import Path

import pytest
from gyrostar.transport.linkrate import PRESETS

GYROSTAR = [str(Path(sys.executable).parent / "gyrostar")]


@pytest.fixture(scope="module")
def links():
    res = subprocess.run(GYROSTAR + ["bench", "driver", "--quick", "--json", "-q"], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    return {k[5:]: v for k, v in json.loads(res.stdout)["driver"].items() if k.startswith("link_")}


def test_every_preset_reports_its_floor_as_the_hand_sum(links):
    assert set(links) == set(PRESETS)
    for name, fig in links.items():
        p = PRESETS[name]
        for case in ("rest", "5dps"):
            down = fig[f"bytes_per_frame_{case}"]["down"]
            hand = 5.0 + 1e3 * (p.latency_s + down / p.bytes_per_s) + 1.25
            assert fig["exposure_to_output_floor_ms"][case] == pytest.approx(hand, rel=1e-9)


def test_only_usb_high_speed_leaves_room_under_9_ms(links):
    floor = {k: v["exposure_to_output_floor_ms"]["5dps"] for k, v in links.items()}
    # full speed: 5 + 1 ms frame + ~1.2 ms of bytes + 1.25 — under 9 ms only with no host at all
    assert 8.0 < floor["usb-fs"] < 9.0 and floor["uart-3m"] > 9.0 and floor["uart-921k"] > 15.0
    assert floor["usb-hs"] < 6.6 and floor["usb-fs"] - floor["usb-hs"] > 1.5
