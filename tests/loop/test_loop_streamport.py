"""The streaming head port against the head emulator on a paced pty: frames come measured
by the callback given with their window set, the next frame to command is two ahead of the
newest one (more only when the set's wire time needs the lead), a set named for a frame is
used for exactly that frame, and the port's log replays to the same answers without a link."""

import time

import numpy as np
import pytest
from gyrostar.attitude import quat_from_boresight
from gyrostar.clock import MONOTONIC
from gyrostar.recording.logfile import Record
from gyrostar.transport import SerialLink

Q0 = quat_from_boresight(np.radians(83.8), np.radians(-5.4), 0.0)


class _Log:
    """Stands in for the run's LogWriter: keeps the records."""

    def __init__(self):
        self.records = []

    def append(self, kind, payload, channel=0, t_ns=0):
        self.records.append(Record(kind, channel, t_ns, bytes(payload)))


@pytest.fixture(scope="module")
def head():
    from gyrostar.catalog import load_catalog
    from gyrostar.mocks.head_emulator import ConstantRateScene, HeadEmulator
    from gyrostar.mocks.paced_relay import RelayProcess
    from gyrostar.mocks.sky import Sky

    sky = Sky(load_catalog("hip2", 7.0), "xing2012", seed=4)
    em = HeadEmulator(sky, ConstantRateScene(Q0), noise=False)
    path = em.start()
    relay = RelayProcess(path, "usb-fs")
    image = np.minimum(sky.render_frame(Q0, np.zeros(3), noise=False)[0], 0x3FF)
    yield relay, image
    relay.close()
    em.stop()


def _spans(row0):
    return np.array([[w, row0 + r, 100 * w + 7, 100 * w + 15] for w in range(4) for r in range(6)], np.int32)


def _poll_until(port, pred, seconds=2.0):
    t_end = time.monotonic() + seconds
    got = []
    while time.monotonic() < t_end:
        res = port.poll()
        if res is None:
            time.sleep(0.001)
            continue
        got.append(res)
        if pred(res):
            return got
    raise AssertionError(f"no such result in {seconds} s ({len(got)} results)")


def test_frames_measured_targets_two_ahead_and_replay(head):
    from gyrostar.hil.streamport import MAX_FRAMES_AHEAD, SET_LEAD_MARGIN_S, StreamPort, StreamReplay
    from gyrostar.transport.linkrate import preset

    relay, image = head
    log = _Log()
    link = SerialLink(relay.path)
    port = StreamPort(link, MONOTONIC, frame_hz=100.0, link_preset=preset("usb-fs"), poll_log=log)
    sums = lambda values: int(values.astype(np.int64).sum())      # noqa: E731 - the "measurement"
    try:
        port.start(0.010)
        assert port.next_target(time.monotonic())[0] == 0       # not streaming yet
        a, b = _spans(200), _spans(600)
        port.submit_windows(a, 0, sums)
        first = _poll_until(port, lambda r: True, 30.0)[0]    # the emulator may compile (cold numba cache)
        assert first.error is None and first.set_frame == 0
        want_a = np.concatenate([image[r, c0:c1] for _, r, c0, c1 in a])
        assert np.array_equal(first.values, want_a) and first.measured == int(want_a.sum())
        last, now = port.last_frame, time.monotonic()
        k, t_exp = port.next_target(now)
        # two after the newest frame received, later only when the last set's wire time (plus
        # the margin) would not fit before the exposure starts, at most MAX_FRAMES_AHEAD after
        need = preset("usb-fs").wire_time(port.last_set_bytes) + SET_LEAD_MARGIN_S
        assert k >= first.frame + 2 and last + 2 <= k <= port.last_frame + MAX_FRAMES_AHEAD
        assert t_exp - now >= need or k >= last + MAX_FRAMES_AHEAD
        assert t_exp == pytest.approx(port.t_first_host + (k - port.first_frame) * 0.010)
        port.submit_windows(b, k, sums)
        got = _poll_until(port, lambda r: r.set_frame == k and r.frame >= k + 2)
        want_b = np.concatenate([image[r, c0:c1] for _, r, c0, c1 in b])
        # the set named for frame k is used from frame k on, never before; on a loaded host it
        # may arrive after frame k's readout began: then it is late, counted, and used from the
        # next readout (a frame the host could not serve in time is missing: counted as dropped)
        stats = port.stats()
        switched = False
        for r in got:
            if r.set_frame == k:
                switched = True
                assert r.frame >= k and np.array_equal(r.values, want_b) and r.measured == int(want_b.sum())
            else:
                assert not switched and r.set_frame == 0 and np.array_equal(r.values, want_a)
                assert r.frame < k or stats["head_late_sets"] >= 1
        assert switched
        frames = [first.frame] + [r.frame for r in got]
        assert stats["frames_received"] >= len(got) + 1
        assert stats["head_dropped"] >= frames[-1] - frames[0] + 1 - len(frames)    # every gap counted
        # the 600-px set in packed 10-bit at 100 Hz is ≈ 0.09 of usb-fs; measured over the few
        # frames of this test (a late set's frame counted in a short window) it reads up to ~0.12
        assert 0 < stats["link_utilisation"] < 0.2
    finally:
        port.close()
        link.close()
    # the log replays the same answers, without a link, recomputing each measurement
    rp = StreamPort(None, MONOTONIC, frame_hz=100.0, replay=StreamReplay(log.records))
    rp.start(0.010)
    assert rp.info == port.info
    answers = []
    from gyrostar.recording.taps import ReplayExhausted

    n_targets = 0
    try:
        rp.submit_windows(a, 0, sums)
        while True:
            res = rp.poll()
            if res is not None:
                answers.append((res.frame, res.set_frame, res.measured))
                if res.frame == first.frame and n_targets == 0:
                    rp.next_target(0.0)
                    n_targets += 1
                    rp.submit_windows(b, k, sums)
    except ReplayExhausted:
        pass
    assert answers[0] == (first.frame, 0, first.measured)
    assert any(sf == k and m == int(want_b.sum()) for _, sf, m in answers)


def test_target_frame_leaves_the_window_set_its_wire_time():
    """A set must reach the head before its frame's exposure starts: two frames after the
    newest received while the last set's bytes fit the lead on the port's link, one more on
    a link too slow for that (921.6 kBd UART), never more than three."""
    from gyrostar.hil.streamport import MAX_FRAMES_AHEAD, SET_LEAD_MARGIN_S, StreamPort
    from gyrostar.loop.linkbudget import windows_bytes
    from gyrostar.transport.linkrate import preset

    class _NoLink:
        def close(self):
            pass

    def port(link_name, set_spans):
        p = StreamPort(_NoLink(), MONOTONIC, link_preset=preset(link_name))
        p.on, p.first_frame, p.t_first_host, p.last_frame = True, 1, 100.0, 10
        p.last_set_bytes = windows_bytes(set_spans)
        return p

    now = 100.0 + 9 * 0.010 + 0.018          # frame 10 (exposed from 100.09 s) arrived 18 ms after its start
    fast = port("usb-hs", 60)
    assert preset("usb-hs").wire_time(windows_bytes(60)) + SET_LEAD_MARGIN_S < 0.002
    assert fast.next_target(now) == (12, pytest.approx(100.11))
    slow = port("uart-921k", 60)             # 60 spans: ~5.3 ms on the UART, more than the 2 ms lead
    assert preset("uart-921k").wire_time(windows_bytes(60)) > 0.002
    assert slow.next_target(now) == (13, pytest.approx(100.12))
    huge = port("uart-921k", 3000)           # no lead is enough: at most MAX_FRAMES_AHEAD after the newest
    assert huge.next_target(now)[0] == 10 + MAX_FRAMES_AHEAD


def test_time_sync_waits_for_the_downlink_gap_after_a_frame():
    """While streaming, a TIME_SYNC goes only when its request and reply both fit between
    now (or when this client's queued bytes are on the wire) and the head's next readout:
    a reply queued behind frame bytes would make the exchange one-sided."""
    from gyrostar.hil.streamport import SYNC_GAP_MARGIN_S, StreamPort
    from gyrostar.loop.linkbudget import time_sync_bytes
    from gyrostar.transport.linkrate import preset

    class _NoLink:
        def close(self):
            pass

    class _Client:
        uplink_idle_at = float("-inf")

    uart = preset("uart-921k")
    assert time_sync_bytes() == 20 + 36                   # request 6+8+4 B, reply 6+24+4 B, COBS +1, 0x00
    need = uart.wire_time(56) + SYNC_GAP_MARGIN_S         # 0.64 ms on the wire + 1 ms: 1.64 ms
    p = StreamPort(_NoLink(), MONOTONIC, link_preset=uart, exposure_s=0.005)
    p.client = _Client()
    p.on, p.first_frame, p.t_first_host, p.last_frame = True, 1, 100.0, 10
    readout_11 = 100.0 + 10 * 0.010 + 0.005               # frame 11: exposed from 100.10 s, read out 5 ms later
    assert p.sync_fits(readout_11 - need - 1e-6)
    assert not p.sync_fits(readout_11 - need + 1e-6)
    p.client.uplink_idle_at = readout_11 - need + 1e-6    # a window set still on the wire
    assert not p.sync_fits(readout_11 - 0.005)
    p.t_first_host = float("nan")                         # before the stream's first frame time
    assert not p.sync_fits(readout_11 - 0.005)
