"""Every CLI command × every class of bad input: the README's exit code, one line on stderr
naming what is wrong, no traceback; with --json, the error object on stdout.

Inputs are chosen to fail at load (parse, config, file checks), so the table stays fast.
"""

import json
import os
from pathlib import Path

import numpy as np
import pytest
from cli_helpers import gyrostar

USAGE, DEVICE, NOT_AVAILABLE = 2, 3, 4


def _files(d):
    """Bad input files, made once per test in ``d``."""
    (d / "text.npz").write_text("not an npz archive\n")
    np.savez(d / "empty.npz")
    np.save(d / "array.npy", np.zeros(3))
    (d / "array.npy").rename(d / "plain.npz")
    np.savez(d / "no_rate.npz", t=np.arange(10.0))
    np.savez(d / "empty_arrays.npz", t=np.zeros(0), rate=np.zeros((0, 3)))
    stars = {"field": np.repeat(np.arange(4), 3), "uv": np.full((12, 2), 500.0),
             "ref": np.tile([0.0, 0.0, 1.0], (12, 1))}
    np.savez(d / "sigma_nan.npz", uv_sigma=np.full(12, np.nan), **stars)
    np.savez(d / "sigma_short.npz", uv_sigma=np.full(11, 0.1), **stars)
    np.savez(d / "star_short.npz", star_id=np.arange(10), **stars)
    (d / "cells.csv").write_text("field,u,v,ra_deg,dec_deg\n0,1.5,2.5,10.0,20.0\n0,x!,2.5,10.0,20.0\n")
    (d / "fits").mkdir()
    (d / "fits" / "dark1.fits").write_bytes(b"SIMPLE  =                    T" + b"\x00garbage" * 50)
    (d / "notalog.gslog").write_bytes(b"hello, not a log")
    (d / "bad.toml").write_text("[loop\nframe_hz = 1\n")
    (d / "plain.txt").write_text("x")
    (d / "camp").mkdir()
    (d / "camp" / "summary.json").write_text("{}")
    (d / "afile").write_text("x")
    for name in ("fifo.toml", "fifo.gslog", "fifo.npz"):
        os.mkfifo(d / name)              # whoever opens one to read waits for a writer: never here
    (d / "zero.npz").symlink_to("/dev/zero")
    (d / "urandom.csv").symlink_to("/dev/urandom")
    (d / "fast_rate.toml").write_text('name = "fast"\nsegments = [{ seconds = 3.0, rate_dps = [1e6, 0.0, 0.0] }]\n')
    (d / "long.toml").write_text('name = "long"\nduration_s = 1e9\n')
    (d / "nominal_camera.toml").write_text("[camera]\nfocal_length_px = 6666.7\nprincipal_point_px = [511.5, 511.5]\n")
    (d / "stray_no_orbit.toml").write_text('name = "s"\n[stray_light]\nenabled = true\n')
    (d / "orbit_epoch.toml").write_text('name = "s"\n[orbit]\nenabled = true\nepoch_utc = "yesterday"\n')
    (d / "saa_box.toml").write_text('name = "s"\n[radiation]\nenabled = true\nsaa_lat_deg = [10.0, -10.0]\n')
    (d / "corrupt.png").write_bytes(b"\x89PNG\r\n\x1a\n" + b"\x00garbage" * 40)
    (d / "corrupt.tiff").write_bytes(b"II*\x00" + b"\x07garbage" * 40)
    (d / "truncated.jpg").write_bytes(b"\xff\xd8\xff\xe0" + b"\x00" * 30)
    from PIL import Image

    Image.fromarray(np.zeros((480, 640), np.uint8)).save(d / "blank.png")
    return d


def _flatsat(d, section: str, key: str, value: str):
    """The built-in flatsat config with one key changed."""
    from gyrostar.hil.config import default_config_path

    lines, inside = [], False
    for line in default_config_path().read_text().splitlines():
        if line.startswith("["):
            inside = line.strip() == f"[{section}]"
        if inside and line.split("=")[0].strip() == key:
            line = f"{key} = {value}"
        lines.append(line)
    text = "\n".join(lines) + "\n"
    path = d / f"{section}_{key}_{abs(hash(value)):x}.toml"
    path.write_text(text)
    return path


FWHOST = str(Path(__file__).resolve().parents[2] / "hil" / "flatsat_fwhost.toml")

# (id, argv with {d} for the bad-input folder, exit code, words the one line must hold)
CASES = [
    # --- usage: unknown commands, flags, bad numbers
    ("no-command", [], USAGE, ["COMMAND"]),
    ("unknown-command", ["fly"], USAGE, ["fly"]),
    ("run-unknown-flag", ["run", "--bogus"], USAGE, ["gyrostar run: error: unrecognized arguments: --bogus",
                                                      "see gyrostar run --help"]),
    # an unknown flag is named by the target that took the rest, with that target's --help
    ("target-unknown-flag", ["fw", "ping", "/dev/ttyNOPE", "--port", "x"], USAGE,
     ["gyrostar fw ping: error: unrecognized arguments: --port x", "see gyrostar fw ping --help"]),
    ("eval-unknown-flag", ["eval", "starid", "--nope"], USAGE, ["gyrostar eval starid: error", "--nope"]),
    ("run-duration-0", ["run", "--duration", "0"], USAGE, ["--duration"]),
    ("run-duration-nan", ["run", "--duration", "nan"], USAGE, ["--duration"]),
    ("run-duration-inf", ["run", "--duration", "inf"], USAGE, ["--duration"]),
    ("run-duration-word", ["run", "--duration", "ten"], USAGE, ["--duration"]),
    ("run-seed-float", ["run", "--seed", "1.5"], USAGE, ["--seed"]),
    ("run-seed-negative", ["run", "--seed", "-1"], USAGE, ["--seed", "at least 0"]),
    ("run-duration-tiny", ["run", "--duration", "1e-9"], USAGE, ["--duration", "at least"]),
    ("run-fwhost-fast", ["run", "--config", FWHOST, "--fast"], USAGE, ["--fast", "firmware-host"]),
    ("run-fast-realtime", ["run", "--fast", "--realtime", "--duration", "2"], USAGE, ["--fast", "--realtime"]),
    # outputs to another machine without outputs.allow_remote: refused before a run folder exists
    ("run-udp-remote", ["run", "--fast", "--config", ("outputs", "udp", "true"), '+udp_host="192.0.2.1"'], USAGE,
     ["UDP output", "192.0.2.1", "allow_remote"]),
    ("run-tm-remote", ["run", "--fast", "--config", ("outputs", "space_packets", "true"), '+tm_host="192.0.2.1"'],
     USAGE, ["space-packet output", "allow_remote"]),
    ("eval-loop-real-head", ["eval", "loop", "--runs", "1", "--duration", "10", "--out", "{d}/mc",
                             "--config", ("head", "kind", '"serial"'), '+url="/dev/ttyUSB9"'], USAGE, ["emulated"]),
    ("eval-loop-out-holds-campaign", ["eval", "loop", "--runs", "1", "--duration", "10", "--out", "{d}/camp"],
     USAGE, ["already holds"]),
    ("eval-loop-orbit-short", ["eval", "loop", "--orbit", "--runs", "1", "--duration", "5", "--out", "{d}/mco"],
     USAGE, ["--duration", "[10, 86400]"]),
    ("run-orbit-case-malformed", ["run", "--scenario", "mco:12x@30"], USAGE, ["mco:SEED@DURATION"]),
    ("sim-frame-missing-folder", ["sim", "frame", "--out", "{d}/no/x.fits"], USAGE, ["does not exist"]),
    ("sim-frame-dec-200", ["sim", "frame", "--out", "{d}/x.fits", "--ra-deg", "10", "--dec-deg", "200"], USAGE,
     ["--dec-deg"]),
    # --- solve: unreadable images, paths and options (exit 2), a frame with no star (exit 1)
    ("solve-missing", ["solve", "{d}/nope.png"], USAGE, ["nope.png", "no such file"]),
    ("solve-corrupt-png", ["solve", "{d}/corrupt.png"], USAGE, ["corrupt.png", "not a readable PNG"]),
    ("solve-corrupt-tiff", ["solve", "{d}/corrupt.tiff"], USAGE, ["corrupt.tiff", "not a readable TIFF"]),
    ("solve-truncated-jpeg", ["solve", "{d}/truncated.jpg"], USAGE, ["truncated.jpg", "not a readable JPG"]),
    ("solve-corrupt-fits", ["solve", "{d}/fits/dark1.fits"], USAGE, ["dark1.fits"]),
    ("solve-not-an-image", ["solve", "{d}/plain.txt"], USAGE, ["plain.txt", "not an image file"]),
    ("solve-folder-no-image", ["solve", "{d}/camp"], USAGE, ["camp", "no image file"]),
    ("solve-fov-range-reversed", ["solve", "{d}/blank.png", "--fov-range", "30,5"], USAGE, ["--fov-range"]),
    ("solve-fov-outside-range", ["solve", "{d}/blank.png", "--fov-deg", "40"], USAGE, ["--fov-deg", "--fov-range"]),
    ("solve-site-no-time", ["solve", "{d}/blank.png", "--site", "52.0,4.4"], USAGE, ["--site", "--time"]),
    ("solve-site-bad", ["solve", "{d}/blank.png", "--site", "95,4", "--time", "2020-01-01T00:00:00"], USAGE,
     ["--site"]),
    ("solve-camera-unknown", ["solve", "{d}/blank.png", "--camera", "nosuch"], USAGE, ["nosuch"]),
    ("solve-camera-size", ["solve", "{d}/blank.png", "--camera", "xing2012"], USAGE, ["640x480", "1024x1024"]),
    ("cal-camera-images-corrupt", ["calibrate", "camera", "--images", "{d}/corrupt.png", "--report", "{d}/rep"],
     USAGE, ["corrupt.png"]),
    ("cal-camera-images-and-input", ["calibrate", "camera", "{d}/plain.npz", "--images", "{d}/blank.png"], USAGE,
     ["--images"]),
    # --- run: configuration the devices reject (exit 2 naming key and file)
    ("run-config-missing", ["run", "--config", "{d}/nope.toml"], USAGE, ["nope.toml"]),
    ("run-config-not-toml", ["run", "--config", "{d}/bad.toml"], USAGE, ["bad.toml", "TOML"]),
    ("run-config-folder", ["run", "--config", "{d}"], USAGE, []),
    ("run-frame-hz-0", ["run", "--config", ("loop", "frame_hz", "0")], USAGE, ["loop.frame_hz", ".toml"]),
    ("run-frame-hz-neg", ["run", "--config", ("loop", "frame_hz", "-5")], USAGE, ["loop.frame_hz", ".toml"]),
    ("run-frame-hz-nan", ["run", "--config", ("loop", "frame_hz", "nan")], USAGE, ["loop.frame_hz", ".toml"]),
    ("run-frame-apid-shared", ["run", "--config", ("outputs", "tm_frame_apid", "0x0A1")], USAGE,
     ["outputs.tm_frame_apid", "own APID"]),
    ("run-bmi088-range", ["run", "--config", ("gyro", "range_dps", "7")], USAGE, ["gyro.range_dps", "BMI088"]),
    ("run-bmi088-odr", ["run", "--config", ("gyro", "odr_hz", "800")], USAGE, ["gyro.odr_hz", "BMI088"]),
    ("run-bmi088-watermark", ["run", "--config", ("gyro", "fifo_watermark", "1000")], USAGE,
     ["gyro.fifo_watermark", "BMI088"]),
    ("run-l3gd20h-odr", ["run", "--config", ("gyro", "model", '"l3gd20h"'), "+odr_hz=1000"], USAGE,
     ["gyro.odr_hz", "L3GD20H"]),
    ("run-l3gd20h-range", ["run", "--config", ("gyro", "model", '"l3gd20h"'), "+range_dps=250"], USAGE,
     ["gyro.range_dps", "L3GD20H"]),
    ("run-unknown-key", ["run", "--config", ("loop", "frame_hz", "100\nframe_rate = 3")], USAGE, ["frame_rate"]),
    ("run-unknown-scenario", ["run", "--scenario", "nosuch"], USAGE, ["nosuch"]),
    ("run-scenario-empty", ["run", "--scenario", ""], USAGE, ["--scenario", "must not be empty"]),
    ("run-scenario-blank", ["run", "--fast", "--scenario", "  "], USAGE, ["--scenario", "must not be empty"]),
    # a missing device: exit 3 naming it, and no run folder or log (the table checks the runs folder)
    ("run-head-port-missing", ["run", "--duration", "2", "--config", ("head", "kind", '"serial"'),
                               '+url="/dev/ttyACM0"'], DEVICE, ["/dev/ttyACM0", "does not exist"]),
    ("run-scenario-missing-file", ["run", "--scenario", "{d}/nosuch.toml"], USAGE, ["nosuch.toml"]),
    ("run-stray-light-no-orbit", ["run", "--scenario", "{d}/stray_no_orbit.toml"], USAGE,
     ["stray_light", "orbit", "stray_no_orbit.toml"]),
    ("run-orbit-bad-epoch", ["run", "--scenario", "{d}/orbit_epoch.toml"], USAGE, ["orbit.epoch_utc", "yesterday"]),
    ("run-saa-box-inverted", ["run", "--scenario", "{d}/saa_box.toml"], USAGE, ["radiation.saa_lat_deg"]),
    ("run-hazards-fwhost", ["run", "--config", FWHOST, "--scenario", "saa-pass"], USAGE,
     ["orbit environment", "firmware-host"]),
    ("run-out-under-file", ["run", "--out", "/dev/null/x"], USAGE, ["--out", "/dev/null/x"]),
    # --- replay
    ("replay-missing", ["replay", "{d}/nope.gslog"], USAGE, ["nope.gslog"]),
    ("replay-folder", ["replay", "{d}"], USAGE, ["folder"]),
    ("replay-not-a-log", ["replay", "{d}/notalog.gslog"], USAGE, ["not a gyrostar log"]),
    ("replay-export-no-out", ["replay", "{d}/notalog.gslog", "--export", "csv"], USAGE, ["--out"]),
    ("replay-export-missing-folder", ["replay", "{d}/notalog.gslog", "--export", "csv", "--out", "{d}/no/x.csv"],
     USAGE, ["--out", "does not exist"]),
    ("replay-export-format", ["replay", "x.gslog", "--export", "xml"], USAGE, ["--export"]),
    ("replay-out-without-export", ["replay", "{d}/notalog.gslog", "--out", "{d}/x.csv"], USAGE, ["--export"]),
    ("replay-force-without-export", ["replay", "{d}/notalog.gslog", "--force"], USAGE, ["--export"]),
    ("replay-check-with-export", ["replay", "{d}/notalog.gslog", "--check", "--export", "csv", "--out", "{d}/x.csv"],
     USAGE, ["--check"]),
    ("replay-export-onto-existing", ["replay", "{d}/notalog.gslog", "--export", "csv", "--out", "{d}/bad.toml"],
     USAGE, ["exists", "--force"]),
    # --- the live view (rerun-sdk is in the dev extra)
    ("run-view-save-existing", ["run", "--fast", "--view-save", "{d}/bad.toml"], USAGE, ["--view-save", "exists"]),
    ("run-view-save-no-folder", ["run", "--fast", "--view-save", "{d}/no/R.rrd"], USAGE,
     ["--view-save", "does not exist"]),
    ("run-view-serve-port", ["run", "--fast", "--view-serve", "80"], USAGE, ["--view-serve", "at least 1024"]),
    ("replay-view-with-export", ["replay", "{d}/notalog.gslog", "--export", "csv", "--out", "{d}/v.csv",
                                 "--view-save", "{d}/v.rrd"], USAGE, ["--view", "--export"]),
    # --- calibrate: bad inputs name the argument
    ("cal-static-text-npz", ["calibrate", "gyro-static", "{d}/text.npz"], USAGE,
     ["INPUT", "text.npz", "npz"]),
    ("cal-static-empty-npz", ["calibrate", "gyro-static", "{d}/empty.npz"], USAGE,
     ["INPUT", "empty"]),
    ("cal-static-npy", ["calibrate", "gyro-static", "{d}/plain.npz"], USAGE, ["INPUT"]),
    ("cal-static-missing-array", ["calibrate", "gyro-static", "{d}/no_rate.npz"], USAGE,
     ["INPUT", "rate"]),
    ("cal-static-empty-arrays", ["calibrate", "gyro-static", "{d}/empty_arrays.npz"], USAGE,
     ["INPUT", "empty"]),
    ("cal-static-missing-file", ["calibrate", "gyro-static", "{d}/nope.npz"], USAGE, ["INPUT", "nope.npz"]),
    ("cal-static-hours-0", ["calibrate", "gyro-static", "--simulate", "--hours", "0"], USAGE, ["--hours"]),
    ("cal-static-no-source", ["calibrate", "gyro-static"], USAGE, ["--simulate"]),
    ("cal-scale-empty-npz", ["calibrate", "gyro-scale", "{d}/empty.npz"], USAGE,
     ["INPUT", "empty"]),
    ("cal-align-text-npz", ["calibrate", "alignment", "{d}/text.npz"], USAGE, ["INPUT"]),
    ("cal-camera-bad-cell", ["calibrate", "camera", "{d}/cells.csv"], USAGE,
     ["INPUT", "line 3", "'u'"]),
    ("cal-camera-fields-0", ["calibrate", "camera", "--simulate", "--fields", "0"], USAGE, ["--fields"]),
    ("cal-camera-empty-npz", ["calibrate", "camera", "{d}/empty.npz"], USAGE, ["INPUT"]),
    ("cal-camera-sigma-nan", ["calibrate", "camera", "{d}/sigma_nan.npz"], USAGE,
     ["INPUT", "sigma_nan.npz", "sigma"]),
    ("cal-camera-sigma-short", ["calibrate", "camera", "{d}/sigma_short.npz"], USAGE,
     ["INPUT", "sigma_short.npz", "uv_sigma", "(11,)"]),
    ("cal-camera-star-short", ["calibrate", "camera", "{d}/star_short.npz"], USAGE,
     ["INPUT", "star_short.npz", "star_id", "(10,)"]),
    ("cal-dark-corrupt-fits", ["calibrate", "dark", "{d}/fits"], USAGE,
     ["INPUT", "dark1.fits"]),
    ("cal-dark-frames-0", ["calibrate", "dark", "--simulate", "--frames", "0"], USAGE, ["--frames"]),
    ("cal-dark-frames-1", ["calibrate", "dark", "--simulate", "--frames", "1"], USAGE, ["--frames"]),
    ("cal-dark-exposures", ["calibrate", "dark", "--simulate", "--exposures", "0,-1"], USAGE, ["--exposures"]),
    ("cal-dark-empty-npz", ["calibrate", "dark", "{d}/empty.npz"], USAGE, ["INPUT"]),
    ("cal-unknown-target", ["calibrate", "compass"], USAGE, ["compass"]),
    # --- eval, sim, bench, fw
    ("eval-starid-trials-0", ["eval", "starid", "--trials", "0"], USAGE, ["trials"]),
    ("eval-starid-noise-neg", ["eval", "starid", "--position-noise-px", "-1"], USAGE, ["pos_noise_px"]),
    ("eval-starid-scheduler-silent", ["eval", "starid", "--scheduler", "tcp://127.0.0.1:9",
                                      "--scheduler-timeout", "0.5", "--trials", "10"], DEVICE, ["--scheduler"]),
    ("eval-centroid-scenario", ["eval", "centroid", "--scenario", "sim9"], USAGE, ["--scenario"]),
    ("eval-starcount-word", ["eval", "starcount", "--trials", "many"], USAGE, ["--trials"]),
    ("sim-frame-no-out", ["sim", "frame"], USAGE, ["--out"]),
    ("bench-unknown-suite", ["bench", "nosuch"], USAGE, ["nosuch"]),
    ("fw-ping-no-device", ["fw", "ping", "{d}/no-such-tty", "-n", "1"], DEVICE, ["no-such-tty"]),
    ("fw-unknown-target", ["fw", "flash"], USAGE, ["flash"]),
    ("fw-host-no-sensor", ["fw", "host"], USAGE, ["--sensor"]),
    ("fw-host-sensor-folder-missing", ["fw", "host", "--sensor", "{d}/no/x.gspx"], USAGE,
     ["--sensor", "does not exist"]),
    ("fw-host-width-0", ["fw", "host", "--sensor", "{d}/x.gspx", "--width", "0"], USAGE, ["--width"]),
    ("run-calibration-folder", ["run", "--fast", "--calibration", "{d}"], USAGE, ["is a folder"]),
    # --- special files: refused as what they are, never read (replay /dev/zero grew to 24 GB, a FIFO hung)
    ("run-config-dev-zero", ["run", "--config", "/dev/zero"], USAGE,
     ["config file /dev/zero", "character device", "not a regular file"]),
    ("run-config-fifo", ["run", "--config", "{d}/fifo.toml"], USAGE, ["fifo.toml", "FIFO"]),
    ("run-scenario-fifo", ["run", "--fast", "--scenario", "{d}/fifo.toml"], USAGE, ["fifo.toml", "FIFO"]),
    ("run-calibration-dev-zero", ["run", "--fast", "--calibration", "/dev/zero"], USAGE,
     ["calibration file /dev/zero", "character device"]),
    ("run-calibration-fifo", ["run", "--fast", "--calibration", "{d}/fifo.toml"], USAGE, ["fifo.toml", "FIFO"]),
    ("replay-dev-zero", ["replay", "/dev/zero", "--check"], USAGE, ["log /dev/zero", "character device"]),
    ("replay-dev-urandom", ["replay", "/dev/urandom", "--check"], USAGE, ["log /dev/urandom", "character device"]),
    ("replay-fifo", ["replay", "{d}/fifo.gslog"], USAGE, ["fifo.gslog", "FIFO"]),
    ("replay-export-dev-zero", ["replay", "/dev/zero", "--export", "csv", "--out", "{d}/zero.csv"], USAGE,
     ["/dev/zero", "character device"]),
    ("cal-static-dev-zero", ["calibrate", "gyro-static", "{d}/zero.npz"], USAGE, ["INPUT", "zero.npz",
                                                                                  "character device"]),
    ("cal-static-fifo", ["calibrate", "gyro-static", "{d}/fifo.npz"], USAGE, ["INPUT", "fifo.npz", "FIFO"]),
    ("cal-camera-urandom-csv", ["calibrate", "camera", "{d}/urandom.csv"], USAGE,
     ["INPUT", "urandom.csv", "character device"]),
    # --- scenario bounds, checked when it is read (mc:1@1e9 drew for 78 s; 1e6 °/s ran 118 s for 3 s)
    ("run-scenario-mc-too-long", ["run", "--fast", "--scenario", "mc:1@1e9", "--duration", "1"], USAGE,
     ["mc:1@1e9", "86400"]),
    ("run-scenario-rate", ["run", "--fast", "--scenario", "{d}/fast_rate.toml"], USAGE, ["rate_dps", "2000"]),
    ("run-scenario-too-long", ["run", "--fast", "--scenario", "{d}/long.toml", "--duration", "1"], USAGE,
     ["duration_s", "86400"]),
    # --- a UDP host that does not resolve: exit 2 naming the key (it stalled the loop in every sendto)
    ("run-udp-host-unresolvable", ["run", "--fast", "--config", ("outputs", "udp", "true"),
                                   '+udp_host="no.such.host.invalid"', "+allow_remote=true"], USAGE,
     ["outputs.udp_host", "no.such.host.invalid", "does not resolve"]),
    # --- a [camera] table of nominal values and no loop.camera_sigma_px: never a σ of 0
    ("run-camera-table-sigma-0", ["run", "--fast", "--calibration", "{d}/nominal_camera.toml"], USAGE,
     ["camera.residual_rms_px", "loop.camera_sigma_px"]),
    ("fw-arm-run-no-sensor", ["fw", "arm", "--run"], USAGE, ["--sensor"]),
    ("fw-build-unknown-flag", ["fw", "build", "--bogus"], USAGE, ["--bogus"]),
    ("sim-frame-rate-dps", ["sim", "frame", "--out", "{d}/x.fits", "--rate-dps", "1,2"], USAGE, ["--rate-dps"]),
    ("eval-centroid-window", ["eval", "centroid", "--window-k", "0"], USAGE, ["window"]),
    ("eval-starcount-fov", ["eval", "starcount", "--fov-deg", "-1", "--trials", "10"], USAGE, ["fov"]),
]


def _argv(case_argv, d):
    out, extra = [], {}
    for a in case_argv:
        if isinstance(a, str) and a.startswith("+"):
            k, v = a[1:].split("=")
            extra[k] = v
    for a in case_argv:
        if isinstance(a, tuple):
            path = _flatsat(d, *a)
            if extra:
                text = path.read_text()
                for k, v in extra.items():
                    text = "\n".join(f"{k} = {v}" if ln.split("=")[0].strip() == k else ln
                                     for ln in text.splitlines()) + "\n"
                path.write_text(text)
            out.append(str(path))
        elif a.startswith("+"):
            continue
        else:
            out.append(a.replace("{d}", str(d)))
    return out


@pytest.fixture(scope="module")
def bad(tmp_path_factory):
    return _files(tmp_path_factory.mktemp("bad"))


@pytest.mark.parametrize("name,argv,code,words", CASES, ids=[c[0] for c in CASES])
def test_bad_input_one_line_and_exit_code(name, argv, code, words, bad, tmp_path):
    res = gyrostar(_argv(argv, bad), cwd=tmp_path, env={"GYROSTAR_RUNS": str(tmp_path / "runs")}, timeout=60)
    lines = [ln for ln in res.stderr.splitlines() if ln.strip()]
    assert res.returncode == code, (res.returncode, res.stderr)
    assert "Traceback" not in res.stderr and "Traceback" not in res.stdout, res.stderr
    assert len(lines) == 1, res.stderr
    for w in words:
        assert w in lines[0], (w, lines[0])
    assert not (tmp_path / "runs").exists() or not any((tmp_path / "runs").iterdir()), "a failed command left a run"


JSON_CASES = [c for c in CASES if c[0] in ("run-duration-nan", "run-bmi088-odr", "replay-folder",
                                           "cal-static-text-npz", "fw-ping-no-device", "run-unknown-flag",
                                           "solve-corrupt-png")]


@pytest.mark.parametrize("name,argv,code,words", JSON_CASES, ids=[c[0] for c in JSON_CASES])
def test_json_error_object_on_stdout(name, argv, code, words, bad, tmp_path):
    res = gyrostar(_argv(argv, bad) + ["--json"], cwd=tmp_path, env={"GYROSTAR_RUNS": str(tmp_path / "runs")})
    obj = json.loads(res.stdout)
    assert obj["exit_code"] == res.returncode == code
    assert all(w in obj["error"] for w in words), obj


def test_long_error_is_not_wrapped_off_a_terminal(bad, tmp_path):
    """The log handler writes one line however long, when stderr is a pipe."""
    deep = tmp_path / ("a-rather-long-folder-name-" * 4) / "and-a-long-log-file-name-that-does-not-exist.gslog"
    res = gyrostar(["replay", deep], cwd=tmp_path)
    lines = [ln for ln in res.stderr.splitlines() if ln.strip()]
    assert res.returncode == USAGE and len(lines) == 1 and str(deep) in lines[0] and len(lines[0]) > 150


def test_verbosity_flags_at_every_level_of_the_command_line():
    """-v/-vv/-q before or after a command or a target (calibrate camera … -vv was refused)."""
    from gyrostar.cli.main import build_parser

    p = build_parser()
    cases = [(["-vv", "run"], 2), (["run", "-vv"], 2), (["-q", "run"], -1), (["run"], None),
             (["calibrate", "camera", "x.npz", "-vv"], 2), (["calibrate", "-v", "camera", "x.npz"], 1),
             (["eval", "starcount", "-q"], -1), (["fw", "ping", "/dev/ttyACM0", "-v"], 1),
             (["sim", "frame", "--out", "f.fits", "-vv"], 2)]
    for argv, want in cases:
        assert getattr(p.parse_args(argv), "verbose", None) == want, argv


def test_runs_folder_that_is_a_file_names_the_variable(bad, tmp_path):
    res = gyrostar(["run", "--fast", "--duration", "2"], cwd=tmp_path, env={"GYROSTAR_RUNS": str(bad / "afile")},
                   timeout=60)
    assert res.returncode == USAGE and "Traceback" not in res.stderr, res.stderr
    lines = [ln for ln in res.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and "GYROSTAR_RUNS=" in lines[0], res.stderr


@pytest.mark.parametrize("argv", [["run", "--fast", "--duration", "2"],
                                  ["eval", "loop", "--runs", "1", "--duration", "10", "--out", "{d}/mc-cache"]],
                         ids=["run", "eval-loop"])
def test_unwritable_cache_folder_is_exit_2_naming_it_before_compiling(argv, bad, tmp_path):
    """A cache folder that cannot be written (here a path through a file; a read-only HOME alike)
    is refused before a minute of compiling, naming the folder and GYROSTAR_CACHE (it compiled for
    81 s, then exited 3, the device code, with no hint)."""
    cache = bad / "afile" / "cache"
    res = gyrostar(_argv(argv, bad), cwd=tmp_path, env={"GYROSTAR_RUNS": str(tmp_path / "runs"),
                                                        "GYROSTAR_CACHE": str(cache)}, timeout=60)
    lines = [ln for ln in res.stderr.splitlines() if ln.strip()]
    assert res.returncode == USAGE and "Traceback" not in res.stderr, res.stderr
    assert len(lines) == 1 and str(cache) in lines[0] and "GYROSTAR_CACHE" in lines[0], res.stderr
    assert not (tmp_path / "runs").exists() or not any((tmp_path / "runs").iterdir())


def test_read_only_home_cache_names_gyrostar_cache(tmp_path):
    """The default cache under a HOME mounted read-only: exit 2 with the hint to set GYROSTAR_CACHE."""
    from cli_helpers import tmpfs

    home = tmp_path / "home"
    with tmpfs(home, "ro,size=1m", "a read-only HOME needs a tmpfs mount (root)"):
        env = {"HOME": str(home), "XDG_CACHE_HOME": "", "GYROSTAR_CACHE": "", "GYROSTAR_RUNS": str(tmp_path / "runs")}
        res = gyrostar(["run", "--fast", "--duration", "2"], cwd=tmp_path, env=env, timeout=60)
    lines = [ln for ln in res.stderr.splitlines() if ln.strip()]
    assert res.returncode == USAGE, res.stderr
    assert len(lines) == 1 and str(home / ".cache" / "gyrostar") in lines[0], res.stderr
    assert "set GYROSTAR_CACHE to a writable folder" in lines[0]
