"""A run whose kept outputs outgrow the machine's memory is refused before it starts."""

import json
import subprocess
import sys

import pytest
from gyrostar.errors import ConfigError
from gyrostar.hil.run_memory import BYTES_PER_OUTPUT, available_bytes, check_kept_outputs_fit
from gyrostar.loop.record import OUTPUT_DTYPE


def test_bytes_per_output_hold_at_least_the_kept_record():
    assert BYTES_PER_OUTPUT > OUTPUT_DTYPE.itemsize == 804


def test_a_minute_fits_in_a_gigabyte_an_hour_does_not_and_the_suggested_length_does():
    check_kept_outputs_fit(60.0, 400.0, available=10**9)
    with pytest.raises(ConfigError) as exc:
        check_kept_outputs_fit(3600.0, 400.0, available=10**9)
    text = str(exc.value)
    assert "1.0 GB available" in text
    longest = float(text.split("--duration ")[1].split()[0])
    # 0.8 GB usable at 1 148 bytes per output and 420 outputs a second: about 1650 s
    assert 1500 < longest < 1800
    check_kept_outputs_fit(longest, 400.0, available=10**9)
    with pytest.raises(ConfigError):
        check_kept_outputs_fit(longest + 10, 400.0, available=10**9)


def test_meminfo_is_read_and_an_unknown_size_is_not_checked(tmp_path):
    info = tmp_path / "meminfo"
    info.write_text("MemTotal:       24000000 kB\nMemFree:        1000 kB\nMemAvailable:    2000000 kB\n")
    assert available_bytes(str(info)) == 2_000_000 * 1024
    assert available_bytes(str(tmp_path / "missing")) is None
    (tmp_path / "junk").write_text("MemAvailable: lots\n")
    assert available_bytes(str(tmp_path / "junk")) is None
    check_kept_outputs_fit(1e12, 400.0, meminfo=str(tmp_path / "missing"))       # nothing known: no check
    with pytest.raises(ConfigError):
        check_kept_outputs_fit(1e5, 400.0, meminfo=str(info))


def test_the_command_refuses_a_run_longer_than_memory_with_one_line_and_no_folder(tmp_path):
    out = tmp_path / "run"
    proc = subprocess.run([sys.executable, "-m", "gyrostar", "run", "--fast", "--duration", "1e9", "--json",
                           "--no-plots", "--out", str(out)], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2
    assert json.loads(proc.stdout.strip().splitlines()[-1])["exit_code"] == 2
    assert "GB available" in proc.stderr and "Traceback" not in proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1
    assert not out.exists()


def test_a_log_too_large_to_read_back_is_refused_with_the_export_named(tmp_path):
    from gyrostar.hil.run_memory import check_log_fits

    log = tmp_path / "big.gslog"
    log.write_bytes(b"\0" * 1_000_000)                         # 1 MB: a replay takes about 3.8 MB
    check_log_fits(log, replay=True, available=10_000_000)
    with pytest.raises(ConfigError) as exc:
        check_log_fits(log, replay=True, available=4_000_000)
    assert "replaying" in str(exc.value) and "--export" in str(exc.value)
    check_log_fits(log, replay=False, available=4_000_000)     # an export: about 1.6 MB
    with pytest.raises(ConfigError, match="exporting"):
        check_log_fits(log, replay=False, available=1_000_000)
    check_log_fits(tmp_path / "missing.gslog", replay=True, available=1)   # the reader reports it


def test_replay_refuses_a_log_larger_than_memory_before_reading_it(tmp_path, monkeypatch):
    from gyrostar.hil import replay, run_memory

    log = tmp_path / "a.gslog"
    log.write_bytes(b"\0" * 1000)
    monkeypatch.setattr(run_memory, "available_bytes", lambda meminfo="/proc/meminfo": 100)
    with pytest.raises(ConfigError, match="takes about"):
        replay.replay(log)
    with pytest.raises(ConfigError, match="exporting"):
        replay.export(log, "csv", tmp_path / "out.csv")
