"""Fast runs' streamed windows rendered ahead in a forked child (hil.render_ahead): the same
frames to the bit as the emulator renders in-process, eclipses and the scenario origin
forwarded in order, and a child that dies costs only its speed."""

import dataclasses
import os
import signal

import numpy as np
import pytest
from gyrostar.hil import render_ahead
from gyrostar.recording.logfile import RX, read_records

EXP = 10_000    # µs: the exposure the windows are rendered at (the emulator's own, set in _world)

pytestmark = pytest.mark.skipif(not render_ahead.usable(), reason="a render process needs two CPUs "
                                "for this process and a process allowed children")


def _world():
    """A streaming head emulator on the demo's sky and scene, and its truth."""
    from gyrostar.catalog import load_catalog
    from gyrostar.hil import config as hc
    from gyrostar.hil import flatsat
    from gyrostar.mocks.head_emulator import HeadEmulator
    from gyrostar.mocks.sim_preset import load_preset
    from gyrostar.mocks.sky import Sky

    cfg, scen = hc.load_flatsat(), hc.load_scenario("demo")
    sim = load_preset(scen.preset or cfg.sim.preset)
    truth = flatsat.Truth(scen, flatsat.simulated_gyro(cfg, scen, 3), t_origin=50.0)
    sky = Sky(load_catalog(cfg.sim.catalog, scen.mag_limit or cfg.sim.mag_limit), sim, seed=3)
    emu = HeadEmulator(sky, flatsat.ScenarioScene(truth, sim.detector.exposure_s))
    emu.exposure_us = EXP        # an eclipse darkens the sky of the emulator's exposure
    emu.warm_up(truth.q0)
    return emu, truth


def _spans_about(emu, truth, t):
    """9×9 windows (span rows) about the stars the scene puts on the sensor at ``t``."""
    from gyrostar.attitude import quat_to_dcm
    from gyrostar.camera import project_many

    q, _ = emu.scene.at(t)
    sky = emu.sky
    body = np.ascontiguousarray(sky.catalog.vectors @ quat_to_dcm(np.asarray(q)).T)
    uv, ok = project_many(sky.params, body)
    w, h = sky.camera.width_px, sky.camera.height_px
    on = np.flatnonzero(ok & (body[:, 2] > 0) & (uv[:, 0] > 10) & (uv[:, 0] < w - 11) & (uv[:, 1] > 10)
                        & (uv[:, 1] < h - 11))[:8]
    rows = []
    for wid, i in enumerate(on):
        c, r = int(uv[i, 0]), int(uv[i, 1])
        rows += [[wid, row, c - 4, c + 5] for row in range(r - 4, r + 5)]
    return np.array(rows, np.int32)


@pytest.fixture
def pair():
    """``(emulator, its RenderAhead, the same world's emulator rendering here, its truth)``."""
    emu, truth = _world()
    ref, ref_truth = _world()
    ra = render_ahead.RenderAhead(emu)
    emu.renderer = ra
    yield emu, ra, ref, ref_truth
    ra.close()


def test_the_child_renders_what_the_emulator_renders_in_order_with_eclipse_and_origin(pair):
    emu, ra, ref, ref_truth = pair
    truth = emu.scene.truth
    truth.restart(60.0)            # forwarded: the child's scene starts there too
    ref_truth.restart(60.0)
    spans = _spans_about(ref, ref_truth, 60.0)
    assert len(spans) > 20
    handles, expect = [], []
    for k in range(6):
        t = 60.0 + 0.01 * k
        if k == 3:                 # stars off from the fourth frame on (background and noise stay)
            emu.eclipse(True)
            ref.eclipse(True)
        handles.append(ra.submit(spans, t, k + 1, EXP))
        expect.append(ref.render_windows(spans, t, k + 1, EXP))
    ra.discard(handles[1])
    got = [ra.result(h)[0] for h in handles if h != handles[1]]
    for g, e in zip(got, [x for i, x in enumerate(expect) if i != 1]):
        assert g.dtype == np.uint16 and np.array_equal(g, e)
    # the eclipse reached the child: the stars gone, the background (about 20 ADU a pixel) left
    assert expect[0].astype(int).sum() > 1.3 * expect[4].astype(int).sum()
    assert ra.wait_s >= 0.0 and not ra.local
    with pytest.raises(KeyError):
        ra.result(handles[1])


def test_the_child_encodes_the_frame_messages_the_emulator_would(pair):
    emu, ra, ref, ref_truth = pair
    spans = _spans_about(ref, ref_truth, 50.0)
    head = dict(frame=7, set_frame=5, t_start_us=123_456_789, t_end_us=123_466_789, exposure_us=EXP,
                late_sets=1, dropped=2, backpressure=0)
    for fmt in (0, 1):
        h = ra.submit(spans, 50.0 + fmt * 0.01, 3 + fmt, EXP, (head, fmt, 42))
        pixels, messages = ra.result(h)
        expect = ref.render_windows(spans, 50.0 + fmt * 0.01, 3 + fmt, EXP)
        ids, slices = ref.window_set(spans)
        assert np.array_equal(pixels, expect)
        assert messages == ref.frame_messages(head, ids, slices, expect, fmt, 42) and len(messages) >= 1
    # without the header, no messages
    assert ra.result(ra.submit(spans, 50.02, 5, EXP))[1] is None


def test_a_child_that_dies_leaves_its_renders_to_this_process(pair):
    emu, ra, ref, ref_truth = pair
    spans = _spans_about(ref, ref_truth, 50.0)
    h1 = ra.submit(spans, 50.0, 1, EXP)
    assert np.array_equal(ra.result(h1)[0], ref.render_windows(spans, 50.0, 1, EXP))
    os.kill(ra.pid, signal.SIGKILL)
    os.waitpid(ra.pid, 0)
    h2 = ra.submit(spans, 50.01, 2, EXP)
    h3 = ra.submit(spans, 50.02, 3, EXP)
    e2 = ref.render_windows(spans, 50.01, 2, EXP)
    e3 = ref.render_windows(spans, 50.02, 3, EXP)
    assert np.array_equal(ra.result(h3)[0], e3) and np.array_equal(ra.result(h2)[0], e2)
    assert ra.local and "Error" in ra.failed      # EOFError, BrokenPipeError: how the pipe told it


def _run(tmp_path, name, monkeypatch, child: bool):
    from gyrostar.hil import config as hc
    from gyrostar.hil.runner import run_flatsat

    monkeypatch.setattr(render_ahead, "usable", lambda: child)
    cfg = hc.load_flatsat()
    scen = dataclasses.replace(hc.load_scenario("eclipse"))
    outs = []
    folder = tmp_path / name
    res = run_flatsat(cfg, scen, duration=8.0, seed=2, folder=folder, plots=False, status=False, fast=True,
                      on_output=lambda r: outs.append(r.copy()))
    rx = [r.payload for r in read_records(folder / "flatsat.gslog") if r.kind == RX]
    return res, np.concatenate(outs), rx


def test_a_fast_run_streams_the_same_frames_rendered_ahead(tmp_path, monkeypatch):
    """The eclipse scenario (stars off 3–7 s) for 8 s: the head's bytes and the loop's outputs
    are the same with the render process as without it."""
    r1, o1, rx1 = _run(tmp_path, "child", monkeypatch, True)
    r2, o2, rx2 = _run(tmp_path, "here", monkeypatch, False)
    assert "forked child process" in r1["wiring"]["head"] and "forked" not in r2["wiring"]["head"]
    assert r1["frames"] == r2["frames"] > 700
    assert rx1 == rx2
    for key in ("t", "q", "cov", "flags", "mode", "centroid_px", "t_mid", "q_mid"):
        np.testing.assert_array_equal(o1[key], o2[key])
    assert r1["mode_seconds"]["COAST"] > 3.0           # the eclipse, seen alike
    # the loop's CPU leaves out the waits for the child (counted as head work it came out
    # negative); its size moves with the host's load, so only its sign is checked here
    assert r1["cpu_percent"] > 0 and r2["cpu_percent"] > 0


def test_child_polls_without_sleeping_then_gives_up():
    """The child's wait for a request: True at once when one is in the pipe, and False only
    after polling an empty pipe for its whole spin time (then it blocks in the kernel)."""
    import multiprocessing as mp
    import time

    a, b = mp.get_context("fork").Pipe()
    try:
        t0 = time.perf_counter()
        assert render_ahead.await_request(b, 0.02) is False
        assert time.perf_counter() - t0 >= 0.02
        a.send_bytes(b"R")
        t0 = time.perf_counter()
        assert render_ahead.await_request(b, 5.0) is True
        assert time.perf_counter() - t0 < 1.0
        assert b.recv_bytes() == b"R"
    finally:
        a.close()
        b.close()
