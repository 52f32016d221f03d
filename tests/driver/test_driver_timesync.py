"""Time sync between the MCU µs clock and the host monotonic clock, with injected link jitter.

Acceptance: the estimated offset is within 50 µs of the truth with 200 µs of link jitter.
Measured twice: on a simulated link (exact truth, many seeds) and on a real pty to the
head emulator (in its own process, as on the flatsat: an emulator thread sharing the test's
interpreter makes the two link directions unequal) whose replies are held back by a
uniformly random 0..200 µs.
"""

import time

import numpy as np
import pytest
from gyrostar.head import ClockSync, HeadClient
from gyrostar.transport import SerialLink

JITTER_S = 200e-6


@pytest.mark.parametrize("seed", range(5))
def test_offset_and_drift_with_200us_jitter_simulated(seed):
    rng = np.random.default_rng(seed)
    off_us, drift = 5.0e9 * rng.random(), rng.uniform(-50e-6, 50e-6)

    def mcu(t):  # truth: MCU µs at host time t (s)
        return off_us + t * 1e6 * (1 + drift)

    sync = ClockSync()
    errors = []
    t = 1000.0 + rng.random()
    for i in range(400):  # 20 Hz for 20 s
        d_up = 60e-6 + rng.uniform(0, JITTER_S)
        d_down = 60e-6 + rng.uniform(0, JITTER_S)
        rx = mcu(t + d_up)
        turn = 25e-6
        tx = mcu(t + d_up + turn)
        sync.add(t, int(rx), int(tx), t + d_up + turn + d_down)
        if i >= 40:
            truth = mcu(t) - t * 1e6
            errors.append(sync.offset_at(t) - truth)
        t += 0.05
    errors = np.abs(errors)
    print(f"seed {seed}: max |offset error| {errors.max():.1f} µs, median {np.median(errors):.1f} µs, "
          f"drift error {(sync.drift - drift) * 1e6:.2f} ppm")
    assert errors.max() < 50.0
    assert abs(sync.drift - drift) < 5e-6


def test_offset_with_200us_jitter_on_a_pty_and_exposure_mid_time():
    from gyrostar.attitude import quat_from_boresight
    from gyrostar.catalog import load_catalog
    from gyrostar.hil.emuproc import EmulatorProcess
    from gyrostar.mocks.faults import ByteFaults, JitteredLink
    from gyrostar.mocks.head_emulator import ConstantRateScene, HeadEmulator
    from gyrostar.mocks.sky import Sky

    offset_us, drift_ppm = 3_210_987_654, 40.0
    sky = Sky(load_catalog("hip2", 7.5), "xing2012", seed=1)

    def make():   # in a child process, as on the flatsat: its threads never share our interpreter
        faults = ByteFaults(seed=4, jitter_s=JITTER_S)      # head → host
        q0 = quat_from_boresight(1.0, 0.3, 0.0)
        emu = HeadEmulator(sky, ConstantRateScene(q0), mcu_offset_us=offset_us, drift_ppm=drift_ppm, faults=faults)
        emu.warm_up(q0)   # its kernels compiled (cold cache) before it serves, not in the CAPTURE's 1 s timeout
        return emu, None

    up_faults = ByteFaults(seed=5, jitter_s=JITTER_S)   # host → head
    em = EmulatorProcess(make)
    link = SerialLink(em.start())
    try:
        head = HeadClient(JitteredLink(link, up_faults), timeout=1.0, sync_every_s=1e9)
        errors = []
        for i in range(200):
            head.sync(1)
            if i >= 40:
                now = time.monotonic()
                # truth: the emulator's MCU clock is offset_us + t·1e6·(1 + drift) at host time t
                errors.append(head.sync_state.offset_at(now) - (offset_us + now * 1e6 * drift_ppm * 1e-6))
            time.sleep(0.01)
        errors = np.abs(errors)
        delayed = em.byte_fault_counts()["delayed"]
        print(f"pty: max |offset error| {errors.max():.1f} µs, median {np.median(errors):.1f} µs, "
              f"min delay {head.sync_state.min_delay_us:.0f} µs, "
              f"jitter on {delayed} replies")
        assert delayed >= 190 and up_faults.injected["delayed"] >= 190
        # The pty shares two busy cores with everything else: its own scheduling jitter adds to
        # the injected 200 µs, so the bound here is on the median; the clean measurement of the
        # acceptance figure is the simulated-link test above.
        assert np.median(errors) < 50.0 and errors.max() < 150.0
        head.set_windows(np.array([[0, 10, 10, 20]]))
        cap = head.capture(fetch=False)
        t0, t1 = em.last_exposure()
        mid_err = (cap.t_mid_host - 0.5 * (t0 + t1)) * 1e6
        print(f"exposure mid-time error {mid_err:.1f} µs")
        assert abs(mid_err) < 150.0
    finally:
        link.close()
        em.stop()


def _exchange(sync, mcu, t, up_s, down_s, turn_s=25e-6, asym_us=0.0):
    """One TIME_SYNC at host time ``t`` with the given one-way delays (s), into ``sync``."""
    rx = mcu(t + up_s)
    tx = mcu(t + up_s + turn_s)
    sync.add(t, int(round(rx)), int(round(tx)), t + up_s + turn_s + down_s, asym_us)


@pytest.mark.parametrize("seed", range(3))
def test_one_sided_queueing_on_a_busy_link_does_not_bias_the_offset(seed):
    """A streaming UART: most replies wait behind frame bytes (0-7 ms, down only), some
    requests behind a window set (0-6 ms, up only). The NTP midpoint of such exchanges is
    off by half the wait, always the same way; the estimate must not be."""
    rng = np.random.default_rng(seed)
    off_us, drift = 1.0e8 * rng.random(), rng.uniform(-50e-6, 50e-6)

    def mcu(t):
        return off_us + t * 1e6 * (1 + drift)

    sync, errors, midpoints = ClockSync(), [], []
    t = 500.0
    for i in range(300):           # 1 Hz for 300 s (the window keeps the last 256)
        up = 250e-6 + rng.uniform(0, 50e-6) + (rng.uniform(0, 6e-3) if rng.random() < 0.3 else 0.0)
        down = 250e-6 + rng.uniform(0, 50e-6) + (rng.uniform(0, 7e-3) if rng.random() < 0.7 else 0.0)
        _exchange(sync, mcu, t, up, down)
        midpoints.append((up - down) / 2 * 1e6)
        if i >= 30:
            errors.append(sync.offset_at(t) - (mcu(t) - t * 1e6))
        t += 1.0
    errors = np.abs(errors)
    print(f"seed {seed}: max |offset error| {errors.max():.1f} µs (mean midpoint error "
          f"{np.mean(midpoints):.0f} µs), drift error {(sync.drift - drift) * 1e6:.3f} ppm")
    assert np.mean(midpoints) < -500.0           # the one-sided waits bias a midpoint by ~0.7 ms
    assert errors.max() < 30.0
    assert abs(sync.drift - drift) < 0.5e-6


def test_one_late_exchange_after_a_clean_start_does_not_tilt_the_drift():
    """Eight clean exchanges at start, then one a second later whose reply waited 4.6 ms: a
    least-squares line through them took its slope from that one (-1200 ppm); the estimate
    a second on must stay within a few µs."""
    off_us = 123_456_789.0

    def mcu(t):
        return off_us + t * 1e6

    sync = ClockSync()
    for k in range(8):
        _exchange(sync, mcu, 100.0 + k * 0.0015, 500e-6, 500e-6)
    _exchange(sync, mcu, 101.0, 500e-6, 5.1e-3)
    assert abs(sync.offset_at(102.0) - off_us) < 5.0
    assert abs(sync.drift) < 5e-6


def test_a_reply_longer_than_its_request_on_a_slow_wire():
    """921.6 kBd 8N1: the 20-byte request takes 217 µs, the 36-byte reply 391 µs. Without the
    difference the offset is off by half of it, (36 - 20) / 92160 / 2 = 86.8 µs."""
    rate = 92_160.0
    up, down = 20 / rate, 36 / rate

    def mcu(t):
        return 5_000_000.0 + t * 1e6

    plain, known = ClockSync(), ClockSync()
    for k in range(20):
        t = 10.0 + 0.05 * k
        _exchange(plain, mcu, t, up, down)
        _exchange(known, mcu, t, up, down, asym_us=(36 - 20) / rate * 1e6)
    assert plain.offset_at(11.0) - 5_000_000.0 == pytest.approx(-86.8, abs=1.0)
    assert known.offset_at(11.0) - 5_000_000.0 == pytest.approx(0.0, abs=1.0)


@pytest.mark.parametrize("step_s", [3.0, -40.0])
def test_a_clock_step_restarts_the_model(step_s):
    """The MCU clock jumps by ``step_s`` against the host's while the link stays open: +3 s
    is a host suspend (CLOCK_MONOTONIC stops, the MCU counts on), −40 s an MCU reset behind
    a UART. The exchanges before the step describe another clock; kept in the window, their
    minima would hold the offset half-way between the two (±1.5 s, ±20 s) until 256 newer
    ones had pushed them out. Truth by hand: after the step the offset is off_us + step."""
    off_us = 7_000_000_000.0
    step_us = step_s * 1e6
    t_step = 160.0

    def mcu(t):
        return off_us + t * 1e6 + (step_us if t >= t_step else 0.0)

    sync = ClockSync()
    rng = np.random.default_rng(1)
    t = 100.0
    while t < t_step - 0.5:           # 1 Hz, with one-sided waits as on a busy link
        _exchange(sync, mcu, t, 250e-6 + rng.uniform(0, 50e-6),
                  250e-6 + rng.uniform(0, 50e-6) + (rng.uniform(0, 5e-3) if rng.random() < 0.5 else 0.0))
        t += 1.0
    assert abs(sync.offset_at(t) - off_us) < 30.0 and sync.steps == 0
    t = t_step + 0.25
    for k in range(5):
        _exchange(sync, mcu, t, 250e-6 + rng.uniform(0, 50e-6), 250e-6 + rng.uniform(0, 50e-6))
        # from the first exchange after the step on: the new clock's offset
        assert abs(sync.offset_at(t) - (off_us + step_us)) < 60.0, k
        t += 1.0
    assert sync.steps == 1
    assert abs(sync.drift) < 5e-6            # the oscillator's drift is kept: a step is not a slope
    assert abs(sync.mcu_to_host(mcu(t)) - t) < 60e-6


@pytest.mark.parametrize("step_ms", [-5.0, 3.0, 15.0])
def test_a_clock_step_of_a_few_ms_is_found(step_ms):
    """Steps of a few ms (an MCU timer reload, a short host stall of CLOCK_MONOTONIC) at 1 Hz
    syncs on a busy link: found at the first exchange after them, so the offset is the new
    clock's at once. Kept as ordinary exchanges, half of such a step would stay in the
    offset until 256 newer exchanges had pushed the old ones out (at 5 °/s, 7.5 ms of a
    15 ms step is 135″ of attitude). Truth by hand: off_us + step after it."""
    off_us, drift, t_step = 2_000_000_000.0, 37e-6, 230.0
    step_us = step_ms * 1e3

    def mcu(t):
        return off_us + t * 1e6 * (1 + drift) + (step_us if t >= t_step else 0.0)

    def truth(t):
        return mcu(t) - t * 1e6

    rng = np.random.default_rng(3)
    sync = ClockSync()
    for k in range(8):                      # the client's start: 8 exchanges at once
        _exchange(sync, mcu, 100.0 + k * 0.002, 250e-6, 250e-6)
    t = 101.0
    while t < t_step - 0.5:
        _exchange(sync, mcu, t, 250e-6 + rng.uniform(0, 50e-6) + (rng.uniform(0, 6e-3) if rng.random() < 0.3 else 0),
                  250e-6 + rng.uniform(0, 50e-6) + (rng.uniform(0, 7e-3) if rng.random() < 0.7 else 0))
        t += 1.0
    assert sync.steps == 0 and abs(sync.offset_at(t - 1.0) - truth(t - 1.0)) < 30.0
    t = t_step + 0.4
    for k in range(5):
        _exchange(sync, mcu, t, 250e-6 + rng.uniform(0, 50e-6), 250e-6 + rng.uniform(0, 50e-6))
        assert abs(sync.offset_at(t) - truth(t)) < 60.0, k
        t += 1.0
    assert sync.steps == 1


@pytest.mark.parametrize("seed", range(4))
def test_busy_links_fast_oscillators_and_a_head_away_never_count_as_a_step(seed):
    """The step test's tolerance against what the model's own error can be: oscillators up to
    150 ppm off, a start of 8 exchanges in 14 ms (no drift known yet), one-sided waits up to
    7 ms, sync gaps of 1–3 s and a head away for 60 s, 2 000 exchanges: no step found, and
    the offset follows the truth."""
    rng = np.random.default_rng(100 + seed)
    off_us, drift = 1e9 * rng.random(), rng.choice([-1.0, 1.0]) * rng.uniform(50e-6, 150e-6)

    def mcu(t):
        return off_us + t * 1e6 * (1 + drift)

    sync = ClockSync()
    for k in range(8):
        _exchange(sync, mcu, 50.0 + k * 0.002, 250e-6 + rng.uniform(0, 1e-3), 250e-6 + rng.uniform(0, 1e-3))
    t, errors = 51.0, []
    for i in range(2000):
        if i == 1000:
            t += 60.0                         # the head away a minute, the same clock after
        _exchange(sync, mcu, t, 250e-6 + (rng.uniform(0, 6e-3) if rng.random() < 0.3 else rng.uniform(0, 50e-6)),
                  250e-6 + (rng.uniform(0, 7e-3) if rng.random() < 0.7 else rng.uniform(0, 50e-6)))
        if i > 30:
            errors.append(abs(sync.offset_at(t) - (mcu(t) - t * 1e6)))
        t += rng.uniform(1.0, 3.0)
    assert sync.steps == 0
    assert max(errors) < 200.0, max(errors)


def test_queueing_never_counts_as_a_step():
    """A reply that waited 40 ms behind a long frame on a slow wire (or a host that read it
    late) is a one-sided delay: it only adds, so it never looks like a clock step."""
    off_us = 1_000_000.0

    def mcu(t):
        return off_us + t * 1e6

    sync = ClockSync()
    for k in range(20):
        _exchange(sync, mcu, 10.0 + k, 300e-6, 300e-6 + (40e-3 if k % 3 == 0 else 0.0))
        _exchange(sync, mcu, 10.5 + k, 300e-6 + (40e-3 if k % 4 == 0 else 0.0), 300e-6)
    assert sync.steps == 0 and sync.count == 40
    assert abs(sync.offset_at(30.0) - off_us) < 1.0


def test_client_follows_a_head_clock_step_and_says_so(caplog):
    """End to end on the simulated link at its line rate (uart-921k): the head emulator's MCU
    clock jumps 3 s ahead (a host suspend) while the link stays open. The next exchange
    restarts the model — the emulator's own offset is the truth — and the client logs one
    warning with the step."""
    import logging

    from gyrostar.clock import SimulatedClock
    from gyrostar.hil.lockstep import Lockstep, SimHead
    from gyrostar.mocks.head_emulator import HeadEmulator
    from gyrostar.transport.linkrate import preset

    class _Sky:
        class camera:
            width_px = height_px = 64

    clock, dev = SimulatedClock(100.0), SimulatedClock(100.0)
    emu = HeadEmulator(_Sky(), scene=None, clock=dev, mcu_offset_us=50_000_000, drift_ppm=30.0)
    head = SimHead(emu, dev, preset("uart-921k"), Lockstep(clock))
    head.start()
    client = HeadClient(head.open_link(), timeout=0.05, clock=clock, sync_every_s=1e9,
                        link_preset=preset("uart-921k"))
    for _ in range(20):
        client.sync(1)
        clock.set(clock.now() + 0.5)
    t = clock.now()
    assert abs(client.sync_state.offset_at(t) - emu.mcu_offset_us_at(t)) < 5.0
    emu.mcu_offset_us += 3_000_000
    with caplog.at_level(logging.WARNING, logger="gyrostar.head.client"):
        client.sync(1)
    t = clock.now()
    assert client.sync_state.steps == 1
    assert abs(client.sync_state.offset_at(t) - emu.mcu_offset_us_at(t)) < 5.0
    steps = [r.getMessage() for r in caplog.records if "stepped" in r.getMessage()]
    assert len(steps) == 1 and "+3.000 s" in steps[0], steps
    # the model rests on one exchange: the next RESYNC_AFTER_STEP are due at once, then 1 Hz again
    from gyrostar.head.client import RESYNC_AFTER_STEP

    for _ in range(RESYNC_AFTER_STEP):
        assert client.sync_due(clock.now())
        client.sync(1)
    assert not client.sync_due(clock.now()) and len(client.sync_state.exchanges) == 5


@pytest.fixture(scope="module")
def sky():
    from gyrostar.catalog import load_catalog
    from gyrostar.mocks.sky import Sky

    return Sky(load_catalog("hip2", 7.5), "xing2012", seed=3)


def _stepping_head(sky, link_wrap=None):
    """A head emulator on the simulated uart-921k link in lock-step (MCU clock 50 s ahead,
    30 ppm fast), a client with a model from 10 exchanges and 1 Hz syncs turned off."""
    from gyrostar.clock import SimulatedClock
    from gyrostar.hil.lockstep import Lockstep, SimHead
    from gyrostar.mocks.head_emulator import ConstantRateScene, HeadEmulator
    from gyrostar.transport.linkrate import preset

    q0 = np.array([0.0, 0.0, 0.0, 1.0])
    clock, dev = SimulatedClock(100.0), SimulatedClock(100.0)
    emu = HeadEmulator(sky, ConstantRateScene(q0, t0=100.0), clock=dev, mcu_offset_us=50_000_000, drift_ppm=30.0,
                       noise=False)
    head = SimHead(emu, dev, preset("uart-921k"), Lockstep(clock))
    head.start()
    link = head.open_link()
    client = HeadClient(link if link_wrap is None else link_wrap(link), timeout=0.05, clock=clock,
                        sync_every_s=1e9, link_preset=preset("uart-921k"))
    for _ in range(10):
        client.sync(1)
        clock.set(clock.now() + 0.5)
    client.set_windows(np.array([[1, 10, 10, 20], [1, 11, 10, 20]], np.int32))
    return clock, emu, client


def _true_host_s(emu, mcu_us: float, t_near: float) -> float:
    return (mcu_us - emu.mcu_offset_us_at(t_near)) * 1e-6


@pytest.mark.parametrize("how", ["capture", "capture_windows"])
def test_a_capture_after_a_head_clock_step_gets_its_own_time(sky, how):
    """Request mode: the head's clock jumps 3 s ahead between two captures, with the 1 Hz
    time sync far off. The capture's MCU times then map 3 s after its own reply; the client
    re-synchronises on the spot and gives the exposure its true host time (truth: the
    emulator's offset), between the request and the reply."""
    clock, emu, client = _stepping_head(sky)
    before = client.capture()
    assert abs(before.t_mid_host - _true_host_s(emu, 0.5 * (before.t_start_us + before.t_end_us),
                                                before.t_mid_host)) < 20e-6
    clock.set(clock.now() + 0.3)
    emu.mcu_offset_us += 3_000_000
    t_ask = clock.now()
    cap = client.capture() if how == "capture" else client.capture_windows(
        np.array([[1, 10, 10, 20], [1, 11, 10, 20]], np.int32))
    mid_mcu = 0.5 * (cap.t_start_us + cap.t_end_us)
    assert t_ask < cap.t_mid_host < clock.now()
    assert abs(cap.t_mid_host - _true_host_s(emu, mid_mcu, cap.t_mid_host)) < 20e-6
    assert client.stats["capture_clock_resyncs"] == 1 and client.sync_state.steps == 1
    after = client.capture()          # mapped by the restarted model, no further resync
    assert client.stats["capture_clock_resyncs"] == 1
    assert abs(after.t_mid_host - _true_host_s(emu, 0.5 * (after.t_start_us + after.t_end_us),
                                               after.t_mid_host)) < 20e-6


def test_a_capture_that_no_time_sync_explains_is_refused(sky):
    """The same step with every TIME_SYNC reply lost on the way back: the model cannot be
    mended, so the capture is refused with HeadClockError (a DeviceError: one frame lost in
    the loop) instead of being given a time 3 s off."""
    from gyrostar.errors import DeviceError
    from gyrostar.head import HeadClockError
    from gyrostar.protocol import MsgType
    from gyrostar.protocol.defs import REPLY_FLAG
    from gyrostar.protocol.framing import decode_frame

    class DropSyncReplies:
        """The link, less the TIME_SYNC replies once ``on``."""
        on = False

        def __init__(self, link):
            self.link = link

        def recv(self, timeout):
            got = self.link.recv(timeout)
            if self.on and got is not None and decode_frame(got[1]).type == (MsgType.TIME_SYNC | REPLY_FLAG):
                return None
            return got

        def __getattr__(self, name):
            return getattr(self.link, name)

    wrap = []
    clock, emu, client = _stepping_head(sky, lambda link: wrap.append(DropSyncReplies(link)) or wrap[0])
    client.capture()
    emu.mcu_offset_us += 3_000_000
    wrap[0].on = True
    with pytest.raises(HeadClockError, match=r"capture \d+ was stamped \+3\.0\d\d s from its request") as e:
        client.capture()
    assert isinstance(e.value, DeviceError) and client.stats["capture_clock_resyncs"] == 1
