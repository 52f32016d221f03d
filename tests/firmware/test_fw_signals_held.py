"""``fwtools.interrupt.signals_held`` (around the start of the firmware host program): a
Ctrl-C inside the block is delivered when it ends, never inside it — also when the kernel
hands the process-directed signal to another thread (one that does not block it), where a
hold by the calling thread's signal mask alone lets Python raise at once inside the block."""

import os
import signal
import threading

import pytest
from gyrostar.fwtools.interrupt import signals_held


@pytest.mark.parametrize("to_thread", [False, True])
def test_ctrl_c_inside_the_block_is_delivered_after_it(to_thread, ctrl_c_raises, wait_signal_held):
    stop = threading.Event()
    other = threading.Thread(target=stop.wait, daemon=True)
    other.start()
    reached_end_of_block = False
    try:
        with pytest.raises(KeyboardInterrupt):
            with signals_held():
                if to_thread:
                    signal.pthread_kill(other.ident, signal.SIGINT)
                else:
                    os.kill(os.getpid(), signal.SIGINT)
                assert wait_signal_held()     # recorded by the hold, not raised inside the block
                for _ in range(1000):     # bytecode boundaries: a pending handler would run here
                    pass
                reached_end_of_block = True
    finally:
        stop.set()
    assert reached_end_of_block
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler     # handlers put back
