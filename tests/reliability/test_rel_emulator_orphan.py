"""A SIGKILLed flatsat process must not leave its head-emulator child running."""

import os
import signal
import subprocess
import sys
import time

SCRIPT = """
import time
from gyrostar.hil.emuproc import EmulatorProcess

class Emu:
    def stop(self):
        pass

def make():
    return Emu(), None

p = EmulatorProcess(make)
print(p.proc.pid, flush=True)
time.sleep(60)
"""


def _alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as fh:
            return fh.read().split()[2] != "Z"
    except FileNotFoundError:
        return False


def test_emulator_child_exits_when_its_parent_is_killed():
    p = subprocess.Popen([sys.executable, "-c", SCRIPT], stdout=subprocess.PIPE, text=True)
    child = int(p.stdout.readline())
    assert _alive(child)
    os.kill(p.pid, signal.SIGKILL)
    p.wait()
    t_end = time.monotonic() + 10.0
    while _alive(child) and time.monotonic() < t_end:
        time.sleep(0.1)
    assert not _alive(child), "orphaned head emulator still running"
