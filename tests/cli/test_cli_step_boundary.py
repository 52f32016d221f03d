"""A Ctrl-C or SIGTERM during a loop step takes effect when the step ends (the log never holds a
step's inputs without its outputs); between steps it takes effect at once."""

import os
import signal
import time

import pytest
from gyrostar.cli import interrupt


@pytest.fixture(autouse=True)
def python_sigint():
    """Python's own Ctrl-C handler for the test (a shell that starts a background job hands
    it SIGINT ignored), restored after."""
    old = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, old)


def test_signal_inside_a_step_is_held_until_it_ends():
    done = []
    with pytest.raises(KeyboardInterrupt):
        with interrupt.StepBoundary() as b:
            b.inside = True
            os.kill(os.getpid(), signal.SIGINT)
            done.append("rest of the step")          # the step runs to its end
            b.step_done()
            done.append("next step")                 # never reached
    assert done == ["rest of the step"]


def test_signal_between_steps_acts_at_once_and_handlers_come_back():
    before = signal.getsignal(signal.SIGINT)
    with pytest.raises(KeyboardInterrupt):
        with interrupt.StepBoundary():
            os.kill(os.getpid(), signal.SIGINT)
            raise AssertionError("not interrupted")
    assert signal.getsignal(signal.SIGINT) is before


def test_sigterm_under_watch_is_held_and_reported_as_terminated():
    with interrupt.watch():
        with pytest.raises(KeyboardInterrupt):
            with interrupt.StepBoundary() as b:
                b.inside = True
                os.kill(os.getpid(), signal.SIGTERM)
                assert not interrupt.seen()          # held: watch's handler has not run yet
                b.step_done()
        assert interrupt.seen() and interrupt.reason() == "terminated (SIGTERM)"


def test_interrupt_swallowed_by_a_callback_still_ends_the_run(capsys):
    """A Ctrl-C whose KeyboardInterrupt lands in a ``__del__`` (or an import lock's weakref
    callback) is dropped by Python; the run still ends at the next step boundary, and no
    "Exception ignored" traceback is printed."""

    class Dropper:
        def __del__(self):
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(0.05)              # the handler runs here and raises inside __del__

    with interrupt.watch():
        d = Dropper()
        del d                             # the KeyboardInterrupt is swallowed
        assert interrupt.seen()
        with pytest.raises(KeyboardInterrupt):
            with interrupt.StepBoundary():
                raise AssertionError("a step ran after the interrupt")
    err = capsys.readouterr().err
    assert "KeyboardInterrupt" not in err and "Traceback" not in err
