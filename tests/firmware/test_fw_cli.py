"""``gyrostar fw`` targets: ARM sizes within the product limits, ping against the host program."""

import json
import shutil
import subprocess
import sys

import pytest
from gyrostar.fwtools import build

pytest.importorskip("gyrostar.head.client")
from gyrostar.mocks.firmware_host import FirmwareHost  # noqa: E402


def _gyrostar(*args):
    return subprocess.run([sys.executable, "-m", "gyrostar", *args], capture_output=True, text=True, timeout=120)


@pytest.mark.skipif(shutil.which("arm-none-eabi-gcc") is None, reason="arm-none-eabi-gcc not installed (.ci/run)")
def test_fw_arm_reports_sizes_within_limits():
    proc = _gyrostar("fw", "arm", "--json")
    assert proc.returncode == 0, proc.stderr
    sizes = json.loads(proc.stdout)
    assert 2048 < sizes["flash_bytes"] <= 65536
    assert 0 < sizes["static_ram_bytes"] <= 65536
    assert sizes["within_limits"] is True
    # the size summary agrees with the ELF's own section headers
    out = subprocess.run(["arm-none-eabi-size", "-A", str(build.arm_elf_path())], capture_output=True,
                         text=True).stdout
    sec = {p[0]: int(p[1]) for p in (ln.split() for ln in out.splitlines()) if len(p) >= 2 and p[1].isdigit()}
    assert sizes["static_ram_bytes"] == sec.get(".data", 0) + sec[".bss"]


def test_fw_ping_host_program():
    build.build("host")
    with FirmwareHost(64, 32, planes=1) as host:
        proc = _gyrostar("fw", "ping", host.path, "-n", "5", "--json")
    assert proc.returncode == 0, proc.stderr
    res = json.loads(proc.stdout)
    assert res["pings"] == 5 and res["info"]["width"] == 64 and res["info"]["height"] == 32
    assert res["telemetry"]["rx_frames"] == 7  # 5 pings, GET_INFO and the TELEMETRY request itself


def test_fw_ping_bad_url_is_a_device_error():
    proc = _gyrostar("fw", "ping", "/nonexistent/tty", "-n", "1")
    assert proc.returncode == 3
    assert "cannot open serial link" in proc.stderr
