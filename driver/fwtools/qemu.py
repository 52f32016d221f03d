"""Run the real ARM image of the head firmware under QEMU (machine mps2-an385).

:class:`QemuHead` starts ``qemu-system-arm`` with the ELF, the sensor pixel file passed on
the semihosting command line (the firmware reads its windows from it with SYS_SEEK/SYS_READ)
and UART0 on a TCP server socket with ``nodelay=on``; :meth:`QemuHead.link` connects a
:class:`gyrostar.transport.serial_link.SerialLink` to ``socket://127.0.0.1:PORT``,
retrying while QEMU starts.
"""

from __future__ import annotations

import shutil
import socket
import subprocess
import time
from pathlib import Path

from ..errors import DeviceError, NotAvailableError
from .build import arm_elf_path, build

QEMU = "qemu-system-arm"
MACHINE = "mps2-an385"


def missing_tools() -> list[str]:
    """Tools the QEMU route needs that this machine lacks."""
    return [t for t in (QEMU, "arm-none-eabi-gcc") if shutil.which(t) is None]


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def qemu_command(elf: Path, sensor: Path, port: int, machine: str = MACHINE) -> list[str]:
    """The qemu-system-arm command line (commas in the sensor path are escaped for QEMU)."""
    sensor_arg = str(sensor).replace(",", ",,")
    return [QEMU, "-M", machine, "-nographic", "-monitor", "none", "-kernel", str(elf),
            "-semihosting-config", f"enable=on,target=native,arg=gyrostar-head,arg=--sensor,arg={sensor_arg}",
            "-serial", f"tcp:127.0.0.1:{port},server=on,wait=off,nodelay=on"]


class QemuHead:
    """The ARM firmware image under QEMU, serving its UART on ``socket://127.0.0.1:PORT``."""

    def __init__(self, sensor: Path, elf: Path | None = None, port: int | None = None, machine: str = MACHINE):
        missing = missing_tools()
        if missing:
            raise NotAvailableError(f"the QEMU route needs {', '.join(missing)} (see .ci/run)")
        self.elf = Path(elf) if elf else build("arm") and arm_elf_path()
        self.sensor = Path(sensor)
        if not self.sensor.exists():
            raise DeviceError(f"sensor pixel file {self.sensor} does not exist")
        self.port = port or _free_port()
        self.machine = machine
        self.proc: subprocess.Popen | None = None

    @property
    def url(self) -> str:
        return f"socket://127.0.0.1:{self.port}"

    def start(self) -> str:
        self.proc = subprocess.Popen(qemu_command(self.elf, self.sensor, self.port, self.machine),
                                     stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
        return self.url

    def link(self, timeout: float = 5.0):
        """Connect a SerialLink, retrying every 5 ms until QEMU listens (or ``timeout`` s)."""
        from ..transport.serial_link import SerialLink

        t_end = time.monotonic() + timeout
        while True:
            if self.proc is not None and self.proc.poll() is not None:
                err = self.proc.stderr.read().decode(errors="replace")
                raise DeviceError(f"QEMU exited with code {self.proc.returncode}: {err.strip()}")
            try:
                return SerialLink(self.url)
            except DeviceError:
                if time.monotonic() > t_end:
                    raise
                time.sleep(0.005)

    def stop(self) -> None:
        if self.proc is not None and self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout=3)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        self.proc = None

    def __enter__(self):
        self.start()
        return self

    def __exit__(self, *exc):
        self.stop()
