"""Streaming head: window plans kept by frame until their pixels come back (StreamPlans)."""

import math

from gyrostar.loop.stream_plans import KEEP_FRAMES, START_EVERY_S, StreamPlans


def test_plans_kept_by_frame_and_dropped_when_too_old():
    p = StreamPlans()
    for f in range(1, 21):
        p.add(f, {"frame": f})
    assert p.get(20) == {"frame": 20} and p.get(20 - KEEP_FRAMES) == {"frame": 12}
    assert p.get(20 - KEEP_FRAMES - 1) is None          # older than 8 frames behind the newest
    assert p.get(99) is None


def test_each_target_commanded_once_and_a_restart_forgets_every_plan():
    p = StreamPlans()
    assert p.target_new(5) and not p.target_new(5) and not p.target_new(4)
    assert p.target_new(6)
    p.add(6, "plan")
    p.restart()
    assert p.get(6) is None and p.last_commanded == 0
    assert p.target_new(3)                               # the new stream counts from its own frames


def test_starting_sets_paced():
    p = StreamPlans()
    assert p.start_due(10.0)
    assert not p.start_due(10.0 + START_EVERY_S / 2)
    assert p.start_due(10.0 + START_EVERY_S)
    assert p.last_commanded == 0 and math.isclose(p.start_wait, 10.0 + 2 * START_EVERY_S)
