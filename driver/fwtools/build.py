"""Build the head firmware through ``firmware/Makefile`` (host program, unit tests, ARM image)."""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

from ..errors import GyrostarError, NotAvailableError
from .protogen import repo_root

TARGETS = ("host", "test", "arm")


class BuildError(GyrostarError):
    """make failed; the message carries the tail of its output."""


def firmware_dir() -> Path:
    return repo_root() / "firmware"


def host_binary_path() -> Path:
    return firmware_dir() / "build" / "host" / "gyrostar-head"


def arm_elf_path() -> Path:
    return firmware_dir() / "build" / "arm" / "gyrostar-head.elf"


def build(target: str) -> str:
    """Run ``make -C firmware TARGET``; return its output. Raises BuildError / NotAvailableError."""
    if target not in TARGETS:
        raise BuildError(f"unknown firmware target {target!r}; one of {TARGETS}")
    if shutil.which("make") is None:
        raise NotAvailableError("make is not installed")
    if target == "arm" and shutil.which("arm-none-eabi-gcc") is None:
        raise NotAvailableError("arm-none-eabi-gcc is not installed (apt-get install gcc-arm-none-eabi "
                                "libnewlib-arm-none-eabi)")
    proc = subprocess.run(["make", "-s", "-C", str(firmware_dir()), target], capture_output=True, text=True)
    out = proc.stdout + proc.stderr
    if proc.returncode:
        raise BuildError(f"make {target} failed:\n" + "\n".join(out.splitlines()[-25:]))
    return out


def arm_sizes(output: str) -> dict:
    """Parse the size lines ``make arm`` prints into a dict of byte counts."""
    m = re.search(r"flash (\d+) B.*?static RAM \.data\+\.bss (\d+) B.*?pixel line buffer (\d+) B; stack (\d+) B",
                  output)
    if not m:
        raise BuildError(f"cannot find the size summary in make arm output:\n{output}")
    flash, ram, line, stack = map(int, m.groups())
    return {"flash_bytes": flash, "static_ram_bytes": ram, "line_buffer_bytes": line, "stack_bytes": stack,
            "flash_limit": 65536, "ram_limit": 65536}
