"""The firmware's host program as the flatsat's head, fed by a sensor process.

:class:`gyrostar.mocks.firmware_host.FirmwareHost` runs ``firmware/build/host/gyrostar-head``
on a pty; its sensor is a memory-mapped pixel file. A child process (``fork``) plays the
sensor and follows the firmware's own exposures: at each CAPTURE's exposure start the
program announces (number, t_start, length) on a Unix datagram socket
(:class:`gyrostar.mocks.firmware_host.ExposureSocket`); the child renders the sky
(:class:`gyrostar.mocks.sky.Sky`) for exactly ``[t_start, t_start + T]`` at the scenario's
attitude and rates (the program's clock is the host's CLOCK_MONOTONIC), publishes the frame
tagged with that exposure and wakes the program, which reads its windows only from the
frame carrying the tag — waiting for it past the exposure end when the render is late, and
failing the CAPTURE (SENSOR_BUSY) rather than serving another exposure's frame.

Pixels within 16 px of every star's path are rendered fresh with their noise each frame;
the rest of the sensor is one rendered star-less frame (its noise frozen), since only the
pixels around stars are ever read while tracking.

The client talks to a relay pty: :class:`gyrostar.mocks.paced_relay.RelayProcess` carrying
bytes at the configured link preset's line rate (or, with no preset, an unpaced relay);
link corruption is injected there on the firmware → client bytes
(:class:`gyrostar.mocks.faults.ByteFaults`).
"""

from __future__ import annotations

import multiprocessing as mp
import os
import select
import threading
import tty
from multiprocessing.connection import wait as mp_wait

import numpy as np

from ..cli.interrupt import ignore_in_child, signals_held
from ..errors import DeviceError

BOX = 16


class _Sensor:
    """Renders announced exposures: star boxes over a star-less frame, per exposure length."""

    def __init__(self, catalog, sim, truth, seed):
        self.catalog, self.sim, self.truth, self.seed = catalog, sim, truth, seed
        self._skies: dict[int, tuple] = {}
        self.frame = 0
        self.eclipse = False

    def _sky(self, exposure_us: int):
        got = self._skies.get(exposure_us)
        if got is None:
            from ..mocks.sky import Sky

            sky = Sky(self.catalog, self.sim.with_exposure(exposure_us * 1e-6), seed=self.seed)
            saved = sky.electrons.copy()
            sky.electrons[:] = 0.0
            static, _ = sky.render_frame(self.truth.q0, np.zeros(3), frame=0)
            sky.electrons[:] = saved
            got = self._skies[exposure_us] = (sky, static)
        return got

    def static(self, exposure_us: int) -> np.ndarray:
        return self._sky(exposure_us)[1]

    def render(self, t0: float, exposure_us: int) -> np.ndarray:
        """The frame of the exposure starting at host time ``t0`` (s), uint16 (H, W)."""
        sky, static = self._sky(exposure_us)
        t_exp = exposure_us * 1e-6
        self.frame += 1
        img = static.copy()
        if self.eclipse:
            return img
        q0 = self.truth.q_at(t0, "sensor")
        rates = self.truth.rates(t0 + (np.arange(8) + 0.5) * t_exp / 8)
        exp = sky.expose(q0, rates)
        inf = exp.truth.in_field
        if np.any(inf):
            w, h = sky.camera.width_px, sky.camera.height_px
            spans = _box_spans(exp.truth.uv[inf], w, h)
            pix = np.minimum(sky.readout_windows(exp, spans, frame=self.frame), 0x3FF)
            widths = spans[:, 3] - spans[:, 2]
            rows = np.repeat(spans[:, 1], widths)
            cols = np.repeat(spans[:, 2], widths) + (np.arange(widths.sum()) - np.repeat(
                np.cumsum(widths) - widths, widths))
            img[rows, cols] = pix
        return img


def _sensor_child(conn, pixels, exposures, sim, truth, seed, catalog_name, mag_limit, parent_pid):
    ignore_in_child()        # a terminal's Ctrl-C reaches us too: the parent stops us, no traceback
    from ..catalog import load_catalog

    sensor = _Sensor(load_catalog(catalog_name, mag_limit), sim, truth, seed)
    exposure_us = int(round(sim.detector.exposure_s * 1e6))
    pixels.write_frame(sensor.static(exposure_us))
    sensor.render(truth.t_origin, exposure_us)       # numba kernels loaded before the first exposure
    conn.send(("ready", None))
    while True:
        ready = mp_wait([conn, exposures], timeout=0.5)
        if not ready:
            # the forked child holds the parent's pipe end too, so a killed parent never shows
            # as EOF: watch for being re-parented instead (a SIGKILLed run leaves no sensor)
            if os.getppid() != parent_pid:
                return
            continue
        if conn in ready:
            cmd, arg = conn.recv()
            if cmd == "stop":
                return
            if cmd == "origin":
                truth.restart(arg)
            elif cmd == "eclipse":
                sensor.eclipse = bool(arg)
            conn.send(("ok", None))
        if exposures in ready:
            exp = exposures.latest()
            if exp is not None:
                pixels.write_frame(sensor.render(exp.t_start, exp.exposure_us), exposure=exp.tag)
                exposures.published(exp)


def _box_spans(uv: np.ndarray, w: int, h: int) -> np.ndarray:
    """Spans [star, row, c0, c1) of a (2·BOX+1)² box around each star (boxes may overlap:
    the renderer's counter-based noise gives a pixel the same value in every box)."""
    out = []
    for j, (u, v) in enumerate(uv):
        r0, r1 = max(0, int(v) - BOX), min(h, int(v) + BOX + 1)
        c0, c1 = max(0, int(u) - BOX), min(w, int(u) + BOX + 1)
        if r1 > r0 and c1 > c0:
            rows = np.arange(r0, r1)
            out.append(np.column_stack([np.full(len(rows), j), rows, np.full(len(rows), c0), np.full(len(rows), c1)]))
    return np.ascontiguousarray(np.concatenate(out).astype(np.int32)) if out else np.zeros((0, 4), np.int32)


class _Relay:
    """A pty the client opens, relaying to and from the firmware's pty, corrupting replies."""

    def __init__(self, target: str):
        self.target = target
        self.master, self.slave = os.openpty()
        tty.setraw(self.slave)
        self.path = os.ttyname(self.slave)
        self.faults = None
        self._fw = os.open(target, os.O_RDWR | os.O_NOCTTY)
        tty.setraw(self._fw)
        self._stop = False
        self._thread = threading.Thread(target=self._run, name="fw-relay", daemon=True)
        self._thread.start()

    def _run(self):
        while not self._stop:
            try:
                r, _, _ = select.select([self.master, self._fw], [], [], 0.05)
                for fd in r:
                    data = os.read(fd, 65536)
                    if not data:
                        return
                    if fd == self.master:
                        os.write(self._fw, data)
                    else:
                        if self.faults is not None:
                            data = self.faults.mutate(data)
                        os.write(self.master, data)
            except OSError:
                return

    def close(self):
        self._stop = True
        self._thread.join(timeout=1.0)
        for fd in (self.master, self.slave, self._fw):
            try:
                os.close(fd)
            except OSError:
                pass


class FirmwareHead:
    """The firmware host program plus its sensor process; same control surface as
    :class:`gyrostar.hil.emuproc.EmulatorProcess` (start, disconnect, corruption, eclipse)."""

    def __init__(self, program, sim, truth, seed, simcfg, mag_limit: float, link=None):
        from pathlib import Path

        from ..mocks.firmware_host import FirmwareHost

        cam = sim.camera
        self.host = FirmwareHost(cam.width_px, cam.height_px, binary=Path(program) if program else None,
                                 expose=True)
        self.program = self.host.binary
        self.link = link
        self.relay = None
        self.connected = False
        self.path = None
        self._byte_faults = None       # ByteFaults keyword arguments on the replies, or None
        self._lock = threading.Lock()
        ctx = mp.get_context("fork")
        self.conn, child = ctx.Pipe()
        self.proc = ctx.Process(target=_sensor_child, name="sensor",
                                args=(child, self.host.pixels, self.host.exposures, sim, truth, seed, simcfg.catalog,
                                      mag_limit, os.getpid()),
                                daemon=True)
        with signals_held():   # the child ignores SIGINT (SIGTERM: default) before any signal reaches it
            self.proc.start()
        if not self.conn.poll(120.0):
            self.stop()
            raise DeviceError("the sensor process did not start (catalog load and first render)")
        self.conn.recv()

    def _call(self, cmd, arg=None):
        with self._lock:
            self._call_locked(cmd, arg)

    def _call_locked(self, cmd, arg):
        self.conn.send((cmd, arg))
        if not self.conn.poll(10.0):
            raise DeviceError(f"sensor process did not answer {cmd}")
        self.conn.recv()

    def start(self) -> str:
        fw_path = self.host.start()
        if self.link is not None:
            from ..mocks.paced_relay import RelayProcess

            self.relay = RelayProcess(fw_path, self.link)
        else:
            self.relay = _Relay(fw_path)
        self.set_byte_faults(self._byte_faults)
        self.path = self.relay.path
        self.connected = True
        return self.path

    def disconnect(self) -> None:
        self.connected = False
        if self.relay is not None:
            self.relay.close()
            self.relay = None
        self.host.stop()

    def set_byte_faults(self, settings: dict | None) -> None:
        """Reply-stream faults: :class:`~gyrostar.mocks.faults.ByteFaults` keyword arguments
        (``corrupt_p``, ``drop_p``, ``garbage_p``, ``seed``), or None to stop injecting; kept
        across a reconnect."""
        from ..mocks.faults import ByteFaults

        self._byte_faults = settings
        if isinstance(self.relay, _Relay):
            self.relay.faults = None if settings is None else ByteFaults(**({"seed": 7} | settings))
        elif self.relay is not None:
            self.relay.set_faults(settings)

    def byte_fault_counts(self) -> dict | None:
        """The in-process relay's ByteFaults counters; None when none are active or the relay
        is a process of its own (a paced link: it keeps them)."""
        faults = getattr(self.relay, "faults", None)
        return None if faults is None else faults.counts()

    def eclipse(self, on: bool) -> None:
        self._call("eclipse", on)

    def set_origin(self, t0: float) -> None:
        self._call("origin", t0)

    def open_link(self):
        from ..transport import SerialLink

        if not self.connected:
            raise DeviceError("firmware head is disconnected")
        return SerialLink(self.path)

    def stop(self) -> None:
        self.disconnect()
        try:
            self.conn.send(("stop", None))
        except OSError:
            pass
        self.proc.join(timeout=2.0)
        if self.proc.is_alive():
            self.proc.kill()
        self.host.close()
