"""``cli.interrupt.signals_held`` (around every child start: the firmware host program, the
forked head emulator, link relay and sensor process): a Ctrl-C inside the block is delivered
when it ends, never inside it — also when the kernel hands the process-directed signal to
another thread (one that does not block it), where a hold by the calling thread's signal mask
alone lets Python raise at once inside the block. A forked child started under it ignores
Ctrl-C and ends quietly on SIGTERM (``ignore_in_child``)."""

import multiprocessing as mp
import os
import signal
import threading
import time

import pytest
from gyrostar.cli.interrupt import ignore_in_child, signals_held


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


def _child(conn):
    ignore_in_child()
    conn.send(signal.getsignal(signal.SIGINT) is signal.SIG_IGN)
    time.sleep(30)


def test_a_child_forked_under_the_hold_ignores_ctrl_c_and_ends_at_once_on_sigterm(ctrl_c_raises):
    ctx = mp.get_context("fork")
    conn, child_conn = ctx.Pipe()
    with signals_held():
        proc = ctx.Process(target=_child, args=(child_conn,), daemon=True)
        proc.start()
    try:
        assert conn.poll(10.0) and conn.recv() is True
        assert signal.pthread_sigmask(signal.SIG_BLOCK, set()) & {signal.SIGINT, signal.SIGTERM} == set()
        os.kill(proc.pid, signal.SIGINT)              # a terminal's Ctrl-C reaches the child too
        proc.join(0.3)
        assert proc.is_alive()
        os.kill(proc.pid, signal.SIGTERM)             # a service manager stopping the group
        proc.join(5.0)
        assert proc.exitcode == -signal.SIGTERM       # the default action: no handler, no traceback
    finally:
        if proc.is_alive():
            proc.kill()
