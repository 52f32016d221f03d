"""The coupled loop end to end on the simulated flatsat, its log, and replay.

A short real-time run (head emulator + BMI088 register model, simulator truth), then:
the outputs track the truth, the UDP stream carries the same records, replay reproduces
every output byte, and a run killed with SIGKILL leaves a log whose readable part replays
exactly.
"""

import json
import os
import signal
import socket
import subprocess
import sys
import time

import numpy as np
import pytest
from gyrostar.errors import ConfigError
from gyrostar.hil import config as hc
from gyrostar.hil.replay import export, load_log, replay
from gyrostar.hil.runner import run_flatsat
from gyrostar.loop import record as R
from gyrostar.loop.sinks import decode_datagram


@pytest.fixture(scope="module")
def demo_run(tmp_path_factory):
    folder = tmp_path_factory.mktemp("run")
    cfg = hc.load_flatsat()
    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rx.bind(("127.0.0.1", 0))
    rx.setblocking(False)
    cfg.outputs.udp = True
    cfg.outputs.udp_port = rx.getsockname()[1]
    rx.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 23)
    got = []

    def drain(_records=None):
        # read as the run goes: ~2 MB of datagrams would overflow a receive buffer capped by
        # a stock kernel's net.core.rmem_max (208 kB, so 416 kB) if read only at the end
        while True:
            try:
                got.append(decode_datagram(rx.recv(65535)))
            except BlockingIOError:
                return

    res = run_flatsat(cfg, hc.load_scenario("sim2"), duration=6.0, seed=5, folder=folder, plots=True, status=False,
                      on_output=drain)
    drain()
    rx.close()
    return res, folder, np.concatenate(got) if got else None


def test_run_tracks_truth_and_reports(demo_run):
    res, folder, _ = demo_run
    for key in ("attitude_error_arcsec_1sigma", "latency_p99_ms", "cpu_percent", "overruns", "mode_seconds",
                "frames", "gyro_samples", "samples_lost"):
        assert key in res
    assert res["mode_seconds"]["TRACK"] > 2.5
    assert res["attitude_error_arcsec_1sigma"] < 12.0          # BMI088-class noise gives ~4–6″
    assert res["frames"] > 100 and res["gyro_samples"] > 2000 and res["samples_lost"] == 0
    # the emulated gyro's share is part of the loop thread's CPU, never more
    assert 0.0 < res["device_emulation_cpu_percent"] < res["cpu_percent"]
    # the loop thread's CPU with its idle ticks holds its steps' and more (400 wake-ups a second)
    assert res["cpu_percent"] < res["loop_thread_cpu_percent"] < 100.0
    assert json.loads((folder / "summary.json").read_text())["frames"] == res["frames"]
    for png in ("attitude_error.png", "bias_estimate.png", "latency_histogram.png", "centroid_error.png"):
        assert (folder / png).stat().st_size > 1000
    log = load_log(folder / "flatsat.gslog")
    out = log["outputs"]
    assert np.all(np.diff(out["seq"]) == 1) and np.all(np.diff(out["t"]) > 0)
    track = out["mode"] == R.MODE_TRACK
    assert np.all(out["flags"][track] & R.FLAG_ATTITUDE_VALID)
    assert np.all(out["n_stars"][track] >= 2)


def test_udp_stream_matches_the_log(demo_run):
    res, folder, udp = demo_run
    out = load_log(folder / "flatsat.gslog")["outputs"]
    assert udp is not None and len(udp) >= 0.9 * len(out)
    by_seq = {int(s): i for i, s in enumerate(out["seq"])}
    idx = [by_seq[int(s)] for s in udp["seq"]]
    assert out[idx].tobytes() == udp.tobytes()


def test_replay_is_bit_exact(demo_run):
    res, folder, _ = demo_run
    rep = replay(folder / "flatsat.gslog")
    assert rep["bit_exact"], rep
    assert rep["replayed_outputs"] == rep["recorded_outputs"] == res["gyro_samples"]


def test_export_csv_and_hdf5(demo_run, tmp_path):
    import h5py

    res, folder, _ = demo_run
    info = export(folder / "flatsat.gslog", "csv", tmp_path / "o.csv")
    lines = (tmp_path / "o.csv").read_text().splitlines()
    assert len(lines) == info["outputs"] + 1 and lines[0].startswith("t_monotonic_s,tai_s,seq,mode")
    meta = json.loads((tmp_path / "o.csv-metadata.json").read_text())
    cols = {c["name"]: c for c in meta["tableSchema"]["columns"]}
    assert cols["omega_x"]["unit"] == "rad/s" and cols["tai_s"]["unit"] == "s"
    assert set(lines[0].split(",")) <= set(cols)
    first = dict(zip(lines[0].split(","), lines[1].split(",")))
    tm = meta["time"]                          # TAI = UTC + 37 s (2017 onwards), from the start pair
    assert tm["tai_minus_utc_s"] == 37.0
    t = float(first["t_monotonic_s"])
    assert float(first["tai_s"]) == pytest.approx(tm["tai_at_monotonic0_s"] + t - tm["monotonic_s"], abs=1e-6)
    export(folder / "flatsat.gslog", "hdf5", tmp_path / "o.h5")
    with h5py.File(tmp_path / "o.h5") as h5:
        assert h5["outputs"].shape == (info["outputs"],)
        assert np.array_equal(h5["outputs"]["q"][:], load_log(folder / "flatsat.gslog")["outputs"]["q"])
        assert h5["columns/q_w"].attrs["unit"] == "1" and h5["columns/sigma_theta_x"].attrs["unit"] == "rad"
        assert h5["columns/utc"][0].decode() == first["utc"]


def test_export_never_overwrites_a_log_and_asks_before_a_file(demo_run, tmp_path):
    """--out onto the log itself (or any gyrostar log) is refused even with force; an
    existing export is refused without force and replaced with it; the log is untouched."""
    _, folder, _ = demo_run
    log = folder / "flatsat.gslog"
    before = log.read_bytes()
    for fmt in ("csv", "hdf5", "aem"):
        with pytest.raises(ConfigError, match="is the log being exported"):
            export(log, fmt, log, force=True)
    other = tmp_path / "copy.gslog"
    other.write_bytes(before[:4096])
    with pytest.raises(ConfigError, match="is a gyrostar log"):
        export(log, "csv", other, force=True)
    assert log.read_bytes() == before and other.read_bytes() == before[:4096]
    out = tmp_path / "o.csv"
    export(log, "csv", out)
    first = out.read_bytes()
    out.write_text("keep me")
    with pytest.raises(ConfigError, match="exists"):
        export(log, "csv", out)
    assert out.read_text() == "keep me"
    export(log, "csv", out, force=True)
    assert out.read_bytes() == first


def test_sigkill_leaves_a_replayable_log(tmp_path):
    out = tmp_path / "killed"
    proc = subprocess.Popen([sys.executable, "-m", "gyrostar", "run", "-q", "--scenario", "sim2", "--duration", "30",
                             "--no-plots", "--out", str(out)], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    log = out / "flatsat.gslog"
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and not (log.exists() and log.stat().st_size > 2_000_000):
        time.sleep(0.2)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    assert log.exists(), proc.stderr.read()
    rep = replay(log)
    assert rep["recorded_outputs"] > 400
    assert rep["prefix_exact"], rep
    assert rep["replayed_outputs"] >= rep["recorded_outputs"]
