"""``gyrostar fw`` targets: ARM sizes within the product limits, ping against the host program."""

import json
import os
import shutil
import signal
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


@pytest.mark.parametrize("value", ["0", "-1", "nan", "inf"])
def test_fw_ping_timeout_must_be_a_positive_number(value):
    proc = _gyrostar("fw", "ping", "/nonexistent/tty", "-n", "1", f"--timeout={value}")
    assert proc.returncode == 2 and "--timeout" in proc.stderr and "Traceback" not in proc.stderr


def test_fw_host_link_never_replaces_a_file(tmp_path):
    """``--link`` replaces a stale symlink only: a file (or folder) at the path is refused, exit 2,
    and kept — by the CLI and by the host program itself."""
    build.build("host")
    keep = tmp_path / "precious.txt"
    keep.write_text("data")
    (tmp_path / "dir").mkdir()
    for link in (keep, tmp_path / "dir"):
        proc = _gyrostar("fw", "host", "--sensor", str(tmp_path / "s.gspx"), "--width", "64", "--height", "64",
                         "--link", str(link))
        assert proc.returncode == 2 and "not a symlink" in proc.stderr and "Traceback" not in proc.stderr
    direct = subprocess.run([str(build.host_binary_path()), "--sensor", str(tmp_path / "s.gspx"), "--width", "64",
                             "--height", "64", "--link", str(keep)], capture_output=True, text=True, timeout=30)
    assert direct.returncode == 2 and "not a symlink" in direct.stderr
    assert keep.read_text() == "data" and (tmp_path / "dir").is_dir()
    bad = tmp_path / "not-a-pixel-file"
    bad.write_text("x" * 100)
    direct = subprocess.run([str(build.host_binary_path()), "--sensor", str(bad), "--width", "64", "--height", "64"],
                            capture_output=True, text=True, timeout=30)
    assert direct.returncode == 2 and "not a gyrostar pixel file" in direct.stderr


def _children(pid: int) -> list[int]:
    out = []
    for d in os.listdir("/proc"):
        if d.isdigit():
            try:
                with open(f"/proc/{d}/stat") as fh:
                    if int(fh.read().rsplit(")", 1)[1].split()[1]) == pid:
                        out.append(int(d))
            except (OSError, IndexError, ValueError):
                pass
    return out


def _alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as fh:   # a zombie awaiting reaping counts as gone
            return fh.read().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_fw_host_stops_its_program_when_signalled(tmp_path, sig):
    """``gyrostar fw host`` stopped by SIGTERM (or Ctrl-C) stops the host program before it
    exits (issue 18: SIGTERM left it running): the program is gone the moment the launcher
    is, its pty link is removed, and the CLI says so in one line with exit code 130."""
    build.build("host")
    link = tmp_path / "head-pty"
    proc = subprocess.Popen([sys.executable, "-m", "gyrostar", "fw", "host", "--sensor", str(tmp_path / "px.gspx"),
                             "--width", "64", "--height", "32", "--planes", "1", "--link", str(link)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        line = proc.stdout.readline()
        assert line.startswith("gyrostar-head: pty "), (line, proc.stderr.read() if proc.poll() is not None else "")
        assert link.is_symlink()
        kids = [k for k in _children(proc.pid) if _alive(k)]
        assert len(kids) == 1
        proc.send_signal(sig)
        _, err = proc.communicate(timeout=10)
        assert not _alive(kids[0]), "host program outlived its launcher"
        assert proc.returncode == 130
        assert not link.exists() and not link.is_symlink(), "the program cleaned up (it was stopped, not killed)"
        lines = [ln for ln in err.splitlines() if ln.strip()]
        assert "Traceback" not in err and any("interrupted" in ln for ln in lines), err
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


@pytest.mark.skipif(shutil.which("arm-none-eabi-gcc") is None or shutil.which("qemu-system-arm") is None,
                    reason="arm-none-eabi-gcc and qemu-system-arm needed (.ci/run)")
def test_fw_arm_run_stops_qemu_on_sigterm(tmp_path):
    from gyrostar.mocks.firmware_host import PixelFile

    px = PixelFile(tmp_path / "px.gspx", 64, 32)
    proc = subprocess.Popen([sys.executable, "-m", "gyrostar", "fw", "arm", "--run", "--sensor", str(px.path)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        for line in proc.stdout:
            if "under QEMU" in line:
                break
        kids = [k for k in _children(proc.pid) if _alive(k)]
        assert len(kids) == 1
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=20)
        assert not _alive(kids[0]), "QEMU outlived its launcher"
        assert proc.returncode == 130 and "Traceback" not in err and "interrupted" in err
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def test_fw_spots_lists_the_heads_spots():
    """`gyrostar fw spots` against the host program holding a frame with three stars."""
    import numpy as np

    build.build("host")
    img = np.full((64, 96), 50, np.uint16)
    for r, c, peak in [(10, 20, 900), (40, 70, 600), (30, 40, 300)]:
        img[r - 1:r + 2, c - 1:c + 2] = peak // 3
        img[r, c] = peak
    with FirmwareHost(96, 64, planes=1) as host:
        host.pixels.write_frame(img)
        proc = _gyrostar("fw", "spots", host.path, "--max-spots", "8", "--json")
        bad = _gyrostar("fw", "spots", host.path, "--box", "8")
    assert proc.returncode == 0, proc.stderr
    res = json.loads(proc.stdout)
    assert [s[:2] for s in res["spots"]] == [[10, 20], [40, 70], [30, 40]]
    assert res["background_dn"] == 50.0 and res["candidates"] == 3
    for (r, c, _), (u, v, _) in zip(res["spots"], res["centroids_uv_flux"]):
        assert abs(u - c) < 0.01 and abs(v - r) < 0.01           # symmetric blobs: centroid on the peak
    assert bad.returncode == 2 and "--box 8" in bad.stderr and "Traceback" not in bad.stderr
