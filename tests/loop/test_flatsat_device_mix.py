"""Any mix of real and emulated flatsat devices: refused at load when it cannot work,
a missing device node named with exit 3, and a real serial head beside the emulated gyro.

The "real" serial head here is the firmware host program on a pty, opened as
``head.kind = "serial"`` exactly as a bench would open /dev/ttyACM0.
"""

import subprocess
import sys

import pytest
from gyrostar.errors import ConfigError, DeviceError
from gyrostar.hil import config as hc
from gyrostar.hil.flatsat import preflight


def _cfg(head: dict, gyro: dict, path):
    lines = ["[head]"] + [f"{k} = {v!r}".replace("'", '"') for k, v in head.items()]
    lines += ["[gyro]"] + [f"{k} = {v!r}".replace("'", '"') for k, v in gyro.items()]
    path.write_text("\n".join(lines) + "\n")
    return path


def _gyrostar(*args):
    return subprocess.run([sys.executable, "-m", "gyrostar", *args], capture_output=True, text=True, timeout=120)


def test_missing_serial_port_exits_3_naming_it(tmp_path):
    cfg = _cfg({"kind": "serial", "url": "/dev/ttyGS_NONE7"}, {"kind": "emulator"}, tmp_path / "f.toml")
    r = _gyrostar("run", "--config", str(cfg), "--duration", "1", "--out", str(tmp_path / "run"), "--no-plots")
    assert r.returncode == 3, r.stderr
    assert "/dev/ttyGS_NONE7" in " ".join(r.stderr.split())
    assert "Traceback" not in r.stderr
    assert not (tmp_path / "run").exists()      # refused before the run folder or a log is made


def test_missing_i2c_bus_exits_3_naming_it(tmp_path):
    cfg = _cfg({"kind": "emulator"}, {"kind": "i2c", "i2c_bus": 97}, tmp_path / "f.toml")
    r = _gyrostar("run", "--config", str(cfg), "--duration", "1", "--out", str(tmp_path / "run"), "--no-plots")
    assert r.returncode == 3, r.stderr
    assert "/dev/i2c-97" in " ".join(r.stderr.split())
    assert "Traceback" not in r.stderr


@pytest.mark.parametrize("head, gyro, scenario, words", [
    ({"kind": "serial", "url": "socket://127.0.0.1:9"}, {"kind": "emulator"}, "disconnect", "head-disconnect"),
    ({"kind": "serial", "url": "socket://127.0.0.1:9"}, {"kind": "emulator"}, "corruption", "link-corruption"),
    ({"kind": "serial", "url": "socket://127.0.0.1:9"}, {"kind": "emulator"}, "eclipse", "eclipse"),
    ({"kind": "serial", "url": "socket://127.0.0.1:9"}, {"kind": "emulator"}, "clock_step", "head-clock-step"),
    ({"kind": "firmware-host"}, {"kind": "emulator"}, "clock_step", "keeps its own clock"),
    ({"kind": "emulator"}, {"kind": "emulator", "model": "l3gd20h"}, "sim2", "l3gd20h"),
])
def test_impossible_mix_refused_at_load(tmp_path, head, gyro, scenario, words):
    cfg = hc.load_flatsat(_cfg(head, gyro, tmp_path / "f.toml"))
    with pytest.raises(ConfigError, match=words):
        preflight(cfg, hc.load_scenario(scenario))


def test_gyro_fault_on_real_gyro_refused(tmp_path):
    cfg = hc.load_flatsat(_cfg({"kind": "emulator"}, {"kind": "spi"}, tmp_path / "f.toml"))
    scen = hc.load_scenario("sim2")
    scen.faults = [hc.Fault(kind="gyro-nack", at_s=1.0, seconds=1.0)]
    with pytest.raises(ConfigError, match="gyro-nack"):
        preflight(cfg, scen)


def test_gyro_nack_refused_on_the_emulated_spi_bus(tmp_path):
    cfg = hc.load_flatsat(_cfg({"kind": "emulator"}, {"kind": "emulator", "emulator_bus": "spi"},
                               tmp_path / "f.toml"))
    scen = hc.load_scenario("sim2")
    scen.faults = [hc.Fault(kind="gyro-nack", at_s=1.0, seconds=1.0)]
    with pytest.raises(ConfigError, match="no acknowledge"):
        preflight(cfg, scen)


def test_emulated_gyro_on_spi_tracks_takes_its_wire_time_and_replays(tmp_path):
    """The emulated BMI088 on a fake spidev in fast mode: the loop tracks at the floor's
    scale, every SPI transfer (a status read and a burst per loop step) moves the simulated
    clock by exactly its wire time, 8 bits per byte at gyro.spi_hz, and the log replays
    bit-exactly."""
    from gyrostar.hil.replay import replay
    from gyrostar.hil.runner import run_flatsat
    from gyrostar.mocks.fake_spidev import FakeSpiDev

    cfg = hc.load_flatsat(_cfg({"kind": "emulator"}, {"kind": "emulator", "emulator_bus": "spi"},
                               tmp_path / "f.toml"))
    wire = []
    orig = FakeSpiDev.xfer2

    def xfer2(self, values, *a, **k):
        t0 = self.clock.now() if self.clock is not None else None
        rx = orig(self, values, *a, **k)
        if t0 is not None:
            wire.append((self.clock.now() - t0, len(values), self.max_speed_hz))
        return rx

    FakeSpiDev.xfer2 = xfer2
    try:
        res = run_flatsat(cfg, hc.load_scenario("demo"), duration=3.0, seed=3, folder=tmp_path / "run",
                          plots=False, status=False, fast=True)
    finally:
        FakeSpiDev.xfer2 = orig
    assert "spidev" in res["wiring"]["gyro"]
    assert res["samples_lost"] == 0 and res["frames"] > 200
    assert 0.5 < res["measured_over_floor"] < 2.0
    # a status read and a burst per step; a step at least every FIFO watermark (4 samples)
    assert len(wire) >= 2 * 3.0 * cfg.gyro.odr_hz / cfg.gyro.fifo_watermark
    for dt, n, hz in wire:
        assert dt == pytest.approx(8 * n / hz, rel=1e-9, abs=1e-12)
    assert replay(res["log"])["bit_exact"]


def test_simulated_clock_refused_with_a_real_device(tmp_path):
    cfg = hc.load_flatsat(_cfg({"kind": "serial", "url": "socket://127.0.0.1:9"}, {"kind": "emulator"},
                               tmp_path / "f.toml"))
    with pytest.raises(ConfigError, match="real time"):
        preflight(cfg, hc.load_scenario("bench"), simulated_clock=True)


def test_missing_spidev_is_a_device_error(tmp_path):
    cfg = hc.load_flatsat(_cfg({"kind": "emulator"}, {"kind": "spi", "spi_bus": 9, "spi_device": 3},
                               tmp_path / "f.toml"))
    with pytest.raises(DeviceError, match="/dev/spidev9.3"):
        preflight(cfg, hc.load_scenario("sim2"))


def _camera_cal(tmp_path):
    from gyrostar.calibration import calfile
    from gyrostar.camera import camera_preset

    nom = camera_preset("xing2012")
    path = tmp_path / "cal.toml"
    calfile.write_section(path, "camera", calfile.CameraCal(nom.focal_length_px, (nom.cx_px, nom.cy_px),
                                                            image_size_px=(nom.width_px, nom.height_px),
                                                            residual_rms_px=0.05), "test")
    return path


def test_real_head_without_camera_model_exits_2_naming_the_key(tmp_path):
    cfg = _cfg({"kind": "serial", "url": "socket://127.0.0.1:9"}, {"kind": "emulator"}, tmp_path / "f.toml")
    r = _gyrostar("run", "--config", str(cfg), "--scenario", "bench", "--duration", "1",
                  "--out", str(tmp_path / "run"), "--no-plots")
    assert r.returncode == 2, r.stderr
    assert "camera.focal_length_px" in " ".join(r.stderr.split()) and "Traceback" not in r.stderr
    cal = tmp_path / "cal.toml"
    cal.write_text('[alignment]\nq_gyro_to_camera = [0.0, 0.0, 0.0, 1.0]\ntime_offset_s = 0.0\n')
    r = _gyrostar("run", "--config", str(cfg), "--calibration", str(cal), "--duration", "1",
                  "--out", str(tmp_path / "run2"), "--no-plots")
    assert r.returncode == 2 and "camera.focal_length_px" in " ".join(r.stderr.split()) and str(cal) in r.stderr


def test_real_serial_head_with_emulated_gyro_runs(tmp_path):
    """The bring-up order that used to crash ('NoneType' has no 't_origin'): the emulated gyro
    takes its rates from the simulator, the serial head is a separate program on a pty."""
    from gyrostar.hil.runner import run_flatsat
    from gyrostar.mocks.firmware_host import FirmwareHost, is_built

    if not is_built():
        pytest.skip("firmware host program not built (make fw-host)")
    with FirmwareHost(workdir=str(tmp_path)) as fw:
        cfg = hc.load_flatsat(_cfg({"kind": "serial", "url": fw.path}, {"kind": "emulator"}, tmp_path / "f.toml"))
        cfg.calibration = str(_camera_cal(tmp_path))
        (tmp_path / "run").mkdir()
        res = run_flatsat(cfg, hc.load_scenario("bench"), duration=3.0, seed=1, folder=tmp_path / "run",
                          plots=False, status=False)
    # every sample of the emulated gyro read or counted lost (a loaded host may stall the real-time loop)
    assert res["gyro_samples"] + res["samples_lost"] >= 0.9 * 3.0 * 400 and res["gyro_samples"] >= 0.5 * 3.0 * 400
    # lost-in-space attempts over the pty: FIND_SPOTS on the host program's frame, every 0.5 s
    # (3 s leaves room for a slow start and a timed-out attempt on a loaded machine)
    assert res["counters"]["acquisitions"] >= 2 and res["link"]["requests"] >= res["counters"]["acquisitions"]
    assert res["attitude_error_arcsec_1sigma"] is None          # no truth for a half-real flatsat
    assert "no truth" in res["wiring"]["sky"]


def test_device_cpu_meter_times_calls_and_passes_everything_through():
    """The emulated gyro's CPU meter: return values and exceptions pass through unchanged,
    attributes stay readable, and the thread CPU of each call (here ≥ 20 ms of busy work) is
    added, errors included."""
    import time

    from gyrostar.hil.flatsat import DeviceCpu

    class Dev:
        addr = 0x68

        def busy(self, ms):
            t0 = time.thread_time()
            while time.thread_time() - t0 < ms * 1e-3:
                pass
            return ms

        def fail(self):
            self.busy(20)
            raise OSError(121, "Remote I/O error")

    meter = DeviceCpu()
    dev = meter.wrap(Dev())
    assert dev.addr == 0x68
    assert dev.busy(20) == 20
    assert 0.020 <= meter.cpu_s < 0.2
    with pytest.raises(OSError):
        dev.fail()
    assert 0.040 <= meter.cpu_s < 0.4
