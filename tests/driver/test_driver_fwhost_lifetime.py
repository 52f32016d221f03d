"""A killed launcher never leaves the firmware host program behind (--exit-with-parent)."""

import os
import signal
import subprocess
import sys
import time

import pytest
from gyrostar.mocks.firmware_host import binary_path

LAUNCHER = """
import sys, time
from gyrostar.mocks.firmware_host import FirmwareHost
host = FirmwareHost(64, 64, workdir=sys.argv[1])   # a SIGKILL leaves its files there
host.start()
print(host.proc.pid, flush=True)
time.sleep(60)
"""


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    with open(f"/proc/{pid}/stat") as fh:          # a zombie awaiting reaping counts as gone
        return fh.read().split(")")[-1].split()[0] != "Z"


def test_host_program_exits_when_its_launcher_is_killed(tmp_path):
    if not binary_path().exists():
        pytest.skip("firmware host program not built (make -C firmware host)")
    launcher = subprocess.Popen([sys.executable, "-c", LAUNCHER, str(tmp_path)], stdout=subprocess.PIPE, text=True)
    host_pid = int(launcher.stdout.readline())
    assert _alive(host_pid)
    launcher.send_signal(signal.SIGKILL)
    launcher.wait()
    deadline = time.monotonic() + 5.0
    while time.monotonic() < deadline and _alive(host_pid):
        time.sleep(0.05)
    assert not _alive(host_pid), "host program outlived its killed launcher"
