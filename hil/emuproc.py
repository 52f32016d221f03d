"""The Python head emulator in a child process, so its rendering never holds the loop's GIL.

The child (``fork``) builds the :class:`gyrostar.mocks.head_emulator.HeadEmulator` and serves
its pty exactly as in-process; the parent drives it through a pipe: start (open a pty,
returns its path), disconnect, byte faults (corruption, drops, garbage bursts) and their
counters, eclipse (stars' signal off) and the scenario's
time origin. The emulator's clock is the host monotonic clock in both processes.
"""

from __future__ import annotations

import multiprocessing as mp
import os

from ..cli.interrupt import ignore_in_child, signals_held
from ..errors import DeviceError


def _child(conn, make, parent_pid):
    ignore_in_child()        # a terminal's Ctrl-C reaches us too: the parent stops us, no traceback
    emu, truth = make()
    while True:
        try:
            # the forked child holds the parent's end of the pipe too, so a killed parent
            # never shows as EOF: watch for being re-parented instead (no orphan emulator)
            while not conn.poll(0.5):
                if os.getppid() != parent_pid:
                    emu.stop()
                    return
            cmd, arg = conn.recv()
        except (EOFError, OSError):
            break
        try:
            if cmd == "start":
                reply = emu.start()
            elif cmd == "disconnect":
                emu.disconnect()
                emu.wait_stopped(1.0)
                reply = None
            elif cmd == "faults":
                from ..mocks.faults import ByteFaults

                # ByteFaults keyword arguments {corrupt_p, drop_p, garbage_p, seed}, or None
                emu.faults = None if arg is None else ByteFaults(**({"seed": 7} | arg))
                reply = None
            elif cmd == "fault_counts":
                f = emu.faults
                reply = None if f is None else f.counts()
            elif cmd == "eclipse":
                emu.eclipse(bool(arg))
                reply = None
            elif cmd == "clock_step":
                emu.step_clock(float(arg))
                reply = None
            elif cmd == "origin":
                truth.restart(arg)
                reply = None
            elif cmd == "last_exposure":
                reply = emu.last_exposure_host
            elif cmd == "stop":
                emu.stop()
                conn.send(("ok", None))
                break
            else:
                raise ValueError(f"unknown emulator command {cmd!r}")
            conn.send(("ok", reply))
        except Exception as exc:  # noqa: BLE001 - reported to the parent
            conn.send(("error", repr(exc)))


class EmulatorProcess:
    """Parent-side handle. ``make()`` runs in the child and returns (emulator, truth).
    With ``link`` (a :mod:`gyrostar.transport.linkrate` preset or its name) the client's pty
    is a :class:`gyrostar.mocks.paced_relay.RelayProcess` carrying bytes at that line rate."""

    def __init__(self, make, link=None):
        ctx = mp.get_context("fork")
        self.conn, child = ctx.Pipe()
        self.proc = ctx.Process(target=_child, args=(child, make, os.getpid()), name="head-emulator", daemon=True)
        with signals_held():   # the child ignores SIGINT (SIGTERM: default) before any signal reaches it
            self.proc.start()
        self.path = None
        self.emulator_path = None
        self.link = link
        self.relay = None
        self.connected = False
        self.faults = None

    def _call(self, cmd, arg=None):
        if not self.proc.is_alive():
            raise DeviceError("head emulator process has exited")
        self.conn.send((cmd, arg))
        if not self.conn.poll(30.0):
            raise DeviceError(f"head emulator process did not answer {cmd}")
        status, reply = self.conn.recv()
        if status != "ok":
            raise DeviceError(f"head emulator: {cmd} failed: {reply}")
        return reply

    def start(self) -> str:
        self.path = self.emulator_path = self._call("start")
        if self.link is not None:
            from ..mocks.paced_relay import RelayProcess

            self.relay = RelayProcess(self.emulator_path, self.link)
            self.path = self.relay.path
        self.connected = True
        return self.path

    def disconnect(self) -> None:
        self.connected = False
        if self.relay is not None:
            self.relay.close()
            self.relay = None
        self._call("disconnect")

    def set_byte_faults(self, settings: dict | None) -> None:
        """Reply-stream faults: :class:`~gyrostar.mocks.faults.ByteFaults` keyword arguments
        (``corrupt_p``, ``drop_p``, ``garbage_p``, ``seed``), or None to stop injecting."""
        self._call("faults", settings)

    def byte_fault_counts(self) -> dict | None:
        """The active ByteFaults' counters (writes, mangled, injected bytes/bursts), or None."""
        return self._call("fault_counts")

    def last_exposure(self) -> tuple[float, float] | None:
        """Host (start, end) of the emulator's last exposure (its truth)."""
        return self._call("last_exposure")

    def eclipse(self, on: bool) -> None:
        self._call("eclipse", bool(on))

    def step_clock(self, step_s: float) -> None:
        """The emulated MCU's clock jumps by ``step_s`` (the link stays open)."""
        self._call("clock_step", float(step_s))

    def set_origin(self, t0: float) -> None:
        self._call("origin", float(t0))

    def stop(self) -> None:
        if self.relay is not None:
            self.relay.close()
            self.relay = None
        try:
            if self.proc.is_alive():
                self._call("stop")
        except DeviceError:
            pass
        self.proc.join(timeout=2.0)
        if self.proc.is_alive():
            self.proc.kill()
