"""Start the firmware's host program (``firmware/build/host/gyrostar-head``) on a real pty.

:class:`FirmwareHost` writes the sensor pixel file the program maps (layout in
``firmware/port/posix/hal_posix.h``: 64-byte "GSPX" header, then u16 planes, with a sequence
lock: ``seq`` odd while a frame is being written), starts the program, waits for its
``gyrostar-head: pty <path>`` line and gives that path (``path``/``url``) for
:func:`serial.serial_for_url` or :class:`gyrostar.transport.SerialLink`. ``write_frame``
publishes a new sensor frame (e.g. rendered by :class:`gyrostar.mocks.sky.Sky`). The
program's MCU clock is CLOCK_MONOTONIC in µs, the same clock as ``time.monotonic``.

With ``expose=True`` the sensor follows the firmware's exposures (:class:`ExposureSocket`):
the program announces each exposure start on a Unix datagram socket, the simulator renders
that exposure and publishes it tagged with the exposure (``write_frame(exposure=...)``), and
the firmware reads only the frame carrying the tag (``firmware/port/posix/hal_posix.h``).
"""

from __future__ import annotations

import mmap
import os
import socket
import struct
import subprocess
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from gyrostar.errors import DeviceError, NotAvailableError
from gyrostar.paths import repo_root

HEADER = 64
OFF_SEQ, OFF_FRAME, OFF_TIME, OFF_TEMP = 16, 20, 24, 32
OFF_EXPOSURE = 36          # u32 exposure number, u64 its start (µs): the frame's exposure tag
EXPOSE_MSG = struct.Struct("<4sIQI")   # "GSEX", exposure number, t_start_us, exposure_us


def binary_path() -> Path:
    root = repo_root()
    return (root or Path(".")) / "firmware" / "build" / "host" / "gyrostar-head"


class PixelFile:
    """The memory-mapped sensor file shared with the host program."""

    def __init__(self, path: Path, width: int, height: int, planes: int = 1, temperature_cdeg: int = 2500):
        self.path, self.width, self.height, self.planes = Path(path), width, height, planes
        size = HEADER + 2 * width * height * planes
        head = struct.pack("<4sHHHHHHIIQh", b"GSPX", 1, HEADER, width, height, planes, 10, 0, 0, 0,
                           temperature_cdeg)
        with open(self.path, "wb") as f:
            f.write(head.ljust(HEADER, b"\0"))
            f.truncate(size)
        self._f = open(self.path, "r+b")
        self.map = mmap.mmap(self._f.fileno(), size)
        self.frame = 0

    @classmethod
    def attach(cls, path: Path) -> PixelFile:
        """An existing pixel file (one a running host program may have mapped), mapped as it is:
        never truncated or replaced. :class:`ValueError` for a file that is not a GSPX v1 file."""
        self = cls.__new__(cls)
        self.path = Path(path)
        with open(self.path, "rb") as f:
            head = f.read(HEADER)
            size = os.fstat(f.fileno()).st_size
        if len(head) < HEADER or head[:4] != b"GSPX":
            raise ValueError(f"{path} is not a GSPX pixel file (magic {head[:4]!r})")
        version, header, self.width, self.height, self.planes, bits = struct.unpack_from("<HHHHHH", head, 4)
        if version != 1 or header != HEADER or self.planes not in (1, 2) or bits != 10:
            raise ValueError(f"{path}: GSPX version {version}, header {header}, planes {self.planes}, bits {bits}: "
                             "not the layout this program writes (version 1, 64, 1 or 2, 10)")
        if size != HEADER + 2 * self.width * self.height * self.planes:
            raise ValueError(f"{path}: {size} bytes, not the {self.width}×{self.height}×{self.planes} its header says")
        self._f = open(self.path, "r+b")
        self.map = mmap.mmap(self._f.fileno(), size)
        self.frame = struct.unpack_from("<I", self.map, OFF_FRAME)[0]
        return self

    def write_frame(self, light: np.ndarray, dark: np.ndarray | None = None,
                    exposure: tuple[int, int] | None = None) -> int:
        """Publish one frame (uint16 (H, W)); returns its frame counter. ``exposure`` =
        (number, t_start_us) of the announced exposure it was rendered for."""
        seq = struct.unpack_from("<I", self.map, OFF_SEQ)[0] & ~1
        struct.pack_into("<I", self.map, OFF_SEQ, (seq + 1) & 0xFFFFFFFF)  # odd: being written
        n = self.width * self.height
        light = np.ascontiguousarray(light, "<u2").ravel()
        if light.size != n:
            raise ValueError(f"frame of {light.size} pixels for a {self.width}x{self.height} sensor")
        self.map[HEADER:HEADER + 2 * n] = light.tobytes()
        if dark is not None and self.planes > 1:
            self.map[HEADER + 2 * n:HEADER + 4 * n] = np.ascontiguousarray(dark, "<u2").tobytes()
        self.frame += 1
        struct.pack_into("<IQ", self.map, OFF_FRAME, self.frame, int(time.monotonic() * 1e6))
        struct.pack_into("<IQ", self.map, OFF_EXPOSURE, *(exposure or (0, 0)))
        struct.pack_into("<I", self.map, OFF_SEQ, (seq + 2) & 0xFFFFFFFF)  # even: stable
        return self.frame

    def close(self) -> None:
        try:
            self.map.close()
        except BufferError:
            pass
        self._f.close()


@dataclass(frozen=True)
class Exposure:
    """One exposure the firmware announced: its number, start (µs, CLOCK_MONOTONIC) and
    length (µs), and the program's socket address to wake when its frame is published."""

    number: int
    t_start_us: int
    exposure_us: int
    reply_to: bytes | str

    @property
    def t_start(self) -> float:
        """Start, host s (``time.monotonic``)."""
        return self.t_start_us * 1e-6

    @property
    def tag(self) -> tuple[int, int]:
        return self.number, self.t_start_us


class ExposureSocket:
    """The sensor's end of the exposure hand-shake: a Unix datagram socket at ``path``."""

    def __init__(self, path: Path):
        self.path = Path(path)
        self.sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
        self.sock.bind(str(self.path))
        self.malformed = 0

    def fileno(self) -> int:
        return self.sock.fileno()

    def latest(self) -> Exposure | None:
        """The newest announced exposure waiting (older ones are dropped: the firmware reads
        only its current exposure), or None."""
        last = None
        while True:
            try:
                data, addr = self.sock.recvfrom(64, socket.MSG_DONTWAIT)
            except (BlockingIOError, InterruptedError):
                return last
            if len(data) != EXPOSE_MSG.size or data[:4] != b"GSEX":
                self.malformed += 1
                continue
            _, no, t_us, exp_us = EXPOSE_MSG.unpack(data)
            last = Exposure(no, t_us, exp_us, addr)

    def published(self, exp: Exposure) -> None:
        """Wake the program waiting for ``exp``'s frame (it also sees the header tag)."""
        try:
            self.sock.sendto(b"GSFR" + struct.pack("<I", exp.number), exp.reply_to)
        except OSError:
            pass   # the program went away (disconnect scenario): nothing waits for it

    def close(self) -> None:
        self.sock.close()
        try:
            self.path.unlink()
        except FileNotFoundError:
            pass


class FirmwareHost:
    """The host build of the firmware, serving its UART on a pty."""

    def __init__(self, width: int = 1024, height: int = 1024, planes: int = 1, workdir: str | None = None,
                 binary: Path | None = None, expose: bool = False, expose_wait_ms: int = 200):
        self.binary = Path(binary or binary_path())
        if not self.binary.exists():
            raise NotAvailableError(f"firmware host program not built: {self.binary} (run `make -C firmware host`)")
        self._tmp = tempfile.TemporaryDirectory(prefix="gyrostar-head-", dir=workdir)
        self.pixels = PixelFile(Path(self._tmp.name) / "sensor.gspx", width, height, planes)
        self.exposures = ExposureSocket(Path(self._tmp.name) / "sensor.sock") if expose else None
        self.expose_wait_ms = int(expose_wait_ms)
        self.stderr_tail = ""
        self.proc: subprocess.Popen | None = None
        self.path: str | None = None

    @property
    def url(self) -> str:
        return self.path

    def start(self, timeout: float = 5.0) -> str:
        cmd = [str(self.binary), "--sensor", str(self.pixels.path), "--width", str(self.pixels.width),
               "--height", str(self.pixels.height), "--planes", str(self.pixels.planes), "--exit-with-parent"]
        if self.exposures is not None:
            cmd += ["--expose-socket", str(self.exposures.path), "--expose-wait-ms", str(self.expose_wait_ms)]
        self.proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        t_end = time.monotonic() + timeout
        line = ""
        while time.monotonic() < t_end:
            line = self.proc.stdout.readline()
            if line.startswith("gyrostar-head: pty "):
                self.path = line.split("pty ", 1)[1].strip()
                return self.path
            if self.proc.poll() is not None:
                break
        code = self.proc.poll()
        err = (self.proc.stderr.read() or "").strip().splitlines() if code is not None else []
        self.stop()
        if code is not None:
            said = f": {err[-1]}" if err else " and printed nothing"
            raise DeviceError(f"firmware host program {self.binary} exited with code {code} before it reported "
                              f"its pty{said}")
        raise DeviceError(f"firmware host program {self.binary} did not report its pty within {timeout} s"
                          + (f" (its last line: {line.strip()!r})" if line.strip() else ""))

    def stop(self) -> None:
        if self.proc is not None and self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout=2)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        if self.proc is not None:
            try:
                self.stderr_tail = self.proc.stderr.read()[-2000:]   # e.g. the exposure counts
            except (OSError, ValueError):
                pass
            for f in (self.proc.stdout, self.proc.stderr):
                f.close()
        self.proc = None

    def close(self) -> None:
        self.stop()
        self.pixels.close()
        if self.exposures is not None:
            self.exposures.close()
        self._tmp.cleanup()

    def __enter__(self):
        self.start()
        return self

    def __exit__(self, *exc):
        self.close()


def is_built() -> bool:
    return binary_path().exists() and os.access(binary_path(), os.X_OK)
