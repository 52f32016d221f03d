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
        return HeadEmulator(sky, ConstantRateScene(quat_from_boresight(1.0, 0.3, 0.0)), mcu_offset_us=offset_us,
                            drift_ppm=drift_ppm, faults=faults), None

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
