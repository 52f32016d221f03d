"""The mode machine, transition by transition (gyrostar.loop.modes: pure functions)."""

import pytest
from gyrostar.loop.modes import Action, ModeParams, ModeState, on_acquired, on_head_lost, on_image
from gyrostar.loop.record import MODE_ACQUIRE, MODE_COAST, MODE_TRACK

P = ModeParams(min_stars=2, confirm_images=3, coast_timeout_s=5.0)


def test_acquire_confirmed_by_an_image_goes_to_track():
    s, act = on_image(ModeState(MODE_ACQUIRE, None, 2), 10.0, 2, P)
    assert (s.mode, s.confirm_failures, s.coast_since_s, act) == (MODE_TRACK, 0, None, Action.NONE)


def test_acquire_unconfirmed_image_counts_a_failure():
    s, act = on_image(ModeState(MODE_ACQUIRE, None, 0), 10.0, 1, P)
    assert (s.mode, s.confirm_failures, act) == (MODE_ACQUIRE, 1, Action.NONE)


def test_acquire_too_many_unconfirmed_images_drop_the_identification():
    s = ModeState(MODE_ACQUIRE)
    acts = []
    for k in range(P.confirm_images):
        s, act = on_image(s, 10.0 + k, 0, P)
        acts.append(act)
    assert acts[:-1] == [Action.NONE] * (P.confirm_images - 1)
    assert acts[-1] == Action.LOSE_ATTITUDE | Action.ACQUISITION_FAILED
    assert (s.mode, s.confirm_failures) == (MODE_ACQUIRE, 0)


def test_track_with_enough_stars_stays():
    s0 = ModeState(MODE_TRACK)
    s, act = on_image(s0, 3.0, 5, P)
    assert s == s0 and act == Action.NONE


def test_track_with_few_stars_coasts_from_that_time():
    s, act = on_image(ModeState(MODE_TRACK), 3.0, 1, P)
    assert (s.mode, s.coast_since_s, act) == (MODE_COAST, 3.0, Action.NONE)


def test_coast_stars_back_returns_to_track():
    s, act = on_image(ModeState(MODE_COAST, 3.0), 4.0, 2, P)
    assert (s.mode, s.coast_since_s, act) == (MODE_TRACK, None, Action.NONE)


@pytest.mark.parametrize("t", [3.5, 8.0])      # within the timeout, and exactly at it
def test_coast_few_stars_within_timeout_stays(t):
    s0 = ModeState(MODE_COAST, 3.0)
    s, act = on_image(s0, t, 0, P)
    assert s == s0 and act == Action.NONE


def test_coast_past_timeout_reacquires_at_once():
    s, act = on_image(ModeState(MODE_COAST, 3.0), 8.01, 0, P)
    assert s.mode == MODE_ACQUIRE and s.coast_since_s is None
    assert act == Action.LOSE_ATTITUDE | Action.ACQUIRE_NOW


def test_head_lost_coasts_only_from_track():
    assert on_head_lost(ModeState(MODE_TRACK), 7.0) == ModeState(MODE_COAST, 7.0)
    for s0 in (ModeState(MODE_COAST, 2.0), ModeState(MODE_ACQUIRE, None, 4)):
        assert on_head_lost(s0, 7.0) == s0


def test_acquired_resets_the_confirmation_count():
    assert on_acquired(ModeState(MODE_ACQUIRE, None, 2)) == ModeState(MODE_ACQUIRE, None, 0)


def test_thresholds_come_from_the_config():
    from gyrostar.hil import config as hc
    from gyrostar.hil.flatsat import loop_params

    cfg = hc.load_flatsat()
    cfg.loop.confirm_images, cfg.loop.coast_timeout_s, cfg.loop.min_stars = 7, 2.5, 3
    mp = loop_params(cfg).mode_params()
    assert (mp.confirm_images, mp.coast_timeout_s, mp.min_stars) == (7, 2.5, 3)


def test_a_scenario_may_set_its_own_coast_timeout():
    """A manoeuvre of fast slews (the built-in ``miscal``) sets a short coast timeout so the
    loop re-acquires after each; a scenario without one keeps the config's."""
    from gyrostar.hil import config as hc
    from gyrostar.hil.flatsat import loop_params

    cfg = hc.load_flatsat()
    cfg.loop.coast_timeout_s = 2.5
    assert loop_params(cfg, scen=hc.load_scenario("miscal")).mode_params().coast_timeout_s == 0.3
    assert loop_params(cfg, scen=hc.load_scenario("demo")).mode_params().coast_timeout_s == 2.5


def test_a_scenario_may_set_its_own_acquisition_cadence():
    """``miscal`` tries a lost-in-space image every 0.1 s (re-acquiring soon after each fast
    slew); a scenario without the key keeps the config's."""
    from gyrostar.hil import config as hc
    from gyrostar.hil.flatsat import loop_params

    cfg = hc.load_flatsat()
    cfg.loop.acquire_every_s = 0.7
    assert loop_params(cfg, scen=hc.load_scenario("miscal")).acquire_every_s == 0.1
    assert loop_params(cfg, scen=hc.load_scenario("demo")).acquire_every_s == 0.7
    assert loop_params(cfg).acquire_every_s == 0.7


def test_a_scenario_may_track_more_stars_than_the_config():
    """``miscal`` tracks the 16 stars an output record holds (the config's 12 elsewhere); a
    scenario's count below the config's ``loop.min_stars`` is refused naming both keys."""
    from gyrostar.errors import ConfigError
    from gyrostar.hil import config as hc
    from gyrostar.hil.flatsat import loop_params
    from gyrostar.loop.record import MAX_STARS

    cfg = hc.load_flatsat()
    assert cfg.loop.max_stars == 12
    assert loop_params(cfg, scen=hc.load_scenario("miscal")).max_stars == MAX_STARS == 16
    assert loop_params(cfg, scen=hc.load_scenario("demo")).max_stars == 12
    few = hc.load_scenario("demo")
    few.max_stars = 1
    cfg.loop.min_stars = 2
    with pytest.raises(ConfigError, match=r"max_stars = 1 is below loop.min_stars = 2"):
        loop_params(cfg, scen=few)
