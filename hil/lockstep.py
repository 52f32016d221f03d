"""Fast mode: the flatsat on a simulated clock in lock-step, faster than real time.

``gyrostar run --fast`` runs the same loop, gyro driver, head client and head port as a
real-time run; only the devices and the clock differ:

* :class:`Lockstep` — one simulated clock for every part and a turn-taking rule: either
  the runner's thread (loop steps, time) or the head port's worker runs, never both, and
  the worker runs until it waits for a reply. Time moves only in the runner: to the next
  gyro step, or earlier to the arrival of the reply the worker waits for (or its
  timeout). The order of events is fixed by simulated time alone, so a run is repeatable.
  It has the :class:`gyrostar.loop.scheduler.StepGate` interface the head port calls.
* :class:`SimHead` — the Python head emulator in this process on a device clock, behind a
  link modelled at its line rate (:mod:`gyrostar.transport.linkrate`): every frame takes
  the preset's latency plus its bytes at the sustained rate, one after the other in each
  direction; the head serves requests in order, an exposure takes its time on the device
  clock, and a stream (START_STREAM) runs its exposure grid on that clock: :meth:`SimHead.pump`
  puts each frame on the wire at its readout, whenever the host next reads the link or sends
  to the head (before the head serves what it sent). Faults (disconnect, reply corruption,
  eclipse) as on the emulator process.
* :class:`SimLink` — the packet link to a :class:`SimHead` (the
  :class:`gyrostar.transport.SerialLink` interface: ``send``, ``recv``, ``drain``).

Not modelled in simulated time: the host's compute time (loop steps, rendering, decoding
take none), so fast mode gives the loop's estimation figures at the achieved timing of the
devices and the link; its CPU and latency are measured on the real-time path and by
``gyrostar bench loop``.
"""

from __future__ import annotations

import heapq
import threading
import time

from ..errors import DeviceError, LinkLostError

IDLE, WANT, RUN, OUT, WAIT = range(5)


class Lockstep:
    """Turn-taking between the runner's thread and one device worker on a simulated clock.

    ``clock`` is a :class:`gyrostar.clock.SimulatedClock`. The thread that creates the
    object is the runner: its waits (set-up requests before the run) advance the clock
    themselves; another thread's waits last until the runner moves the clock past them.
    """

    def __init__(self, clock, cpu_clock=time.perf_counter):
        self.clock = clock
        # times the inline jobs (job_cpu_s): they run on the runner's thread with no other
        # thread of the run busy, so its wall clock reads their CPU without a system call
        self.cpu_clock = cpu_clock
        self.runner = threading.current_thread()
        self._cv = threading.Condition(threading.Lock())
        self._state = IDLE
        self._wake_t: float | None = None
        self._running = False
        # the runner's next event (its next step): a worker wait that ends no later than
        # this moves the clock itself, as the runner would at once (no hand-over)
        self.horizon = -float("inf")
        # inline jobs (see run_job): the running job's own time, None outside a job
        self._job_t: float | None = None
        self.inline_jobs = False       # the head port runs its jobs through run_job (no worker)
        self.on_time = None            # f(t): the head's faults due by simulated time t (inline jobs)
        self.on_time_due = None        # f(t) -> bool: on_time(t) would apply one (None: assume so)
        self.job_cpu_s = 0.0           # CPU s the inline jobs took (the head's and its client's work)
        # f() -> s: wall seconds the inline jobs have waited on another process so far (the head
        # emulator's render process, gyrostar.hil.render_ahead), left out of job_cpu_s
        self.job_waits = None

    # -- StepGate interface (called by the head port) ----------------------------------
    def loop_enter(self) -> None:
        """The runner steps only while the worker waits (see :meth:`settle`)."""

    def loop_exit(self, next_wake: float) -> None:
        """Nothing to do: the runner settles the worker after each step."""

    def open(self) -> None:
        """End of the run: the worker runs freely, its waits advance the clock."""
        with self._cv:
            self._running = False
            self._cv.notify_all()

    def worker_enter(self) -> None:
        with self._cv:
            if not self._running:
                self._state = RUN
                return
            self._state = WANT
            self._cv.notify_all()
            while self._state != RUN and self._running:
                self._cv.wait()
            self._state = RUN

    def worker_exit(self) -> None:
        with self._cv:
            self._state = OUT
            self._cv.notify_all()

    # -- inline jobs -------------------------------------------------------------------------
    def now(self) -> float:
        """Simulated time: the running inline job's own time, else the clock's."""
        t = self._job_t
        return self.clock.now() if t is None else t

    def sleep(self, dt: float) -> None:
        if dt > 0:
            self.wait_until(self.now() + dt)

    def run_job(self, fn) -> float:
        """Run a head job at once, on the runner's thread, on its own time line from now: its
        waits move only that job time (and apply the head's faults due by then), never the
        clock the loop steps on. Returns the job's finish time: the loop takes its result at
        its first step from then on, as it would from a worker woken at the same times —
        without two thread hand-overs per reply."""
        self._job_t = self.clock.now()
        waits = self.job_waits
        w0 = waits() if waits is not None else 0.0
        c0 = self.cpu_clock()
        try:
            fn()
        finally:
            t, self._job_t = self._job_t, None
            self.job_cpu_s += self.cpu_clock() - c0 - ((waits() - w0) if waits is not None else 0.0)
        return t

    # -- the runner's side ---------------------------------------------------------------
    def begin(self) -> None:
        """Start the lock-step schedule (after the devices' set-up)."""
        with self._cv:
            self._running = True

    @property
    def wake_time(self) -> float | None:
        """Simulated time the waiting worker wants to be woken at, or None."""
        with self._cv:
            return self._wake_t if self._state == WAIT else None

    def wake(self) -> None:
        """Move the clock to the worker's wake-up time and let it run (then :meth:`settle`)."""
        with self._cv:
            t = self._wake_t
            if self._state != WAIT or t is None:
                return
            if t > self.clock.now():
                self.clock.set(t)
            self._wake_t = None
            self._state = OUT
            self._cv.notify_all()

    def settle(self, port) -> None:
        """Let the worker run until it waits for a reply or has no unfinished job.

        ``port``: the head port (``busy`` — a job submitted and not yet polled;
        ``job_done`` — its result is ready)."""
        with self._cv:
            while True:
                if self._state == WANT:
                    self._state = RUN
                    self._cv.notify_all()
                    continue
                if self._state == RUN:
                    self._cv.wait()
                    continue
                if self._state == WAIT:
                    return
                if not port.busy or port.job_done:
                    return
                # a job is queued but not yet entered, or its post-processing runs outside
                # the gate: wait for the worker (it notifies on entering; done is polled)
                self._cv.wait(timeout=0.0005)

    # -- waits (called by the link) --------------------------------------------------------
    def wait_until(self, t: float) -> None:
        """Block the calling thread until simulated time ``t`` (the runner's own waits and
        every wait outside the schedule move the clock instead; an inline job's waits move
        its own time)."""
        if self._job_t is not None:
            if t > self._job_t:
                if self.on_time is not None:
                    self.on_time(t)
                self._job_t = t
            return
        with self._cv:
            if not self._running or threading.current_thread() is self.runner or t <= self.horizon:
                if t > self.clock.now():
                    self.clock.set(t)
                return
            self._wake_t = t
            self._state = WAIT
            self._cv.notify_all()
            while self._state == WAIT and self._running:
                self._cv.wait()
            if not self._running and t > self.clock.now():
                self.clock.set(t)


class SimHead:
    """The head emulator on a device clock behind a line-rate link model.

    ``emulator`` is a :class:`gyrostar.mocks.head_emulator.HeadEmulator` built on
    ``device_clock`` (a :class:`gyrostar.clock.SimulatedClock` this object sets to each
    request's arrival time); ``preset`` a :class:`gyrostar.transport.linkrate.LinkPreset`.
    """

    def __init__(self, emulator, device_clock, preset, lockstep: Lockstep):
        self.emu = emulator
        self.dev = device_clock
        self.preset = preset
        self.lockstep = lockstep
        self.connected = False
        self.faults = None
        self.url = f"sim://head ({preset.name})"
        self._tx_free = -float("inf")     # host → head wire free from (s)
        self._rx_free = -float("inf")     # head → host wire free from (s)
        self._busy_until = -float("inf")  # the head serves requests one after the other
        self.bytes_out = 0
        self.bytes_in = 0
        self.link = None
        emulator.backlog_source = self.tx_backlog      # the stream's back-pressure sees this wire

    # -- faults / life cycle (the interface the fault plan drives) -------------------------
    def start(self) -> str:
        self.connected = True
        return self.url

    def disconnect(self) -> None:
        self.connected = False
        if self.link is not None:
            self.link.lost = LinkLostError(f"sim link {self.url} closed: head disconnected")

    def stop(self) -> None:
        self.disconnect()

    def set_byte_faults(self, settings: dict | None) -> None:
        """Reply-stream faults: :class:`~gyrostar.mocks.faults.ByteFaults` keyword arguments
        (``corrupt_p``, ``drop_p``, ``garbage_p``, ``seed``), or None to stop injecting."""
        from ..mocks.faults import ByteFaults

        self.faults = None if settings is None else ByteFaults(**({"seed": 7} | settings))

    def byte_fault_counts(self) -> dict | None:
        """The active ByteFaults' counters, or None."""
        return None if self.faults is None else self.faults.counts()

    def eclipse(self, on: bool) -> None:
        self.emu.eclipse(bool(on))

    def step_clock(self, step_s: float) -> None:
        self.emu.step_clock(step_s)

    def set_origin(self, t0: float) -> None:
        """The scenario truth is shared in-process: nothing to forward."""

    def open_link(self) -> SimLink:
        if not self.connected:
            raise DeviceError("head emulator is disconnected")
        self.link = SimLink(self)
        return self.link

    # -- traffic -----------------------------------------------------------------------------
    def _up(self, data: bytes, t: float, chunks: list) -> None:
        """``data`` leaves the head at device time ``t`` (after what the wire already carries):
        appended to ``chunks`` as (arrival at the host, bytes), through the byte faults."""
        out = []
        if self.faults is not None:
            self.faults.write_through(out.append, data, sleep=self.dev.sleep)
        else:
            out.append(data)
        p = self.preset
        for b in out:
            s = max(t, self._rx_free)
            self._rx_free = s + len(b) / p.bytes_per_s
            self.bytes_in += len(b)
            chunks.append((self._rx_free + p.latency_s, b))

    def tx_backlog(self) -> int:
        """Bytes the head has handed to its link that are not yet on the wire at device time
        (the emulator's stream drops a frame above ``stream_tx_backlog_max``, as on its pty)."""
        return max(0, int((self._rx_free - self.dev.now()) * self.preset.bytes_per_s))

    def next_event(self) -> float:
        """Simulated time of the stream's next step (an exposure starts or is read out)."""
        due = self.emu.next_due if self.emu.stream is not None else None
        return float("inf") if due is None else due

    def pump(self, t: float) -> list[tuple[float, bytes]]:
        """Run the head's stream up to simulated time ``t``: every frame read out by then is
        put on the wire at its readout (``(arrival, bytes)`` chunks, in order)."""
        chunks: list = []
        emu = self.emu
        while emu.stream is not None:
            due = emu.next_due
            if due is None or due > t:
                break
            if due > self.dev.now():
                self.dev.set(due)
            msgs = emu.poll_stream(self.dev.now())
            if self.connected:
                for m in msgs:
                    self._up(m, self.dev.now(), chunks)
        return chunks

    def transact(self, data: bytes, t_send: float) -> list[tuple[float, bytes]]:
        """Bytes sent at ``t_send``: their frames served in order (the stream run up to each
        one's arrival first); returns the head's output as ``(arrival time at the host,
        bytes)`` chunks: stream frames and replies in the order they left."""
        p = self.preset
        start = max(t_send, self._tx_free)
        self._tx_free = start + len(data) / p.bytes_per_s
        t_arr = self._tx_free + p.latency_s
        self.bytes_out += len(data)
        chunks: list = []
        for frame in bytes(data).split(b"\x00"):
            if not frame:
                continue
            t_serve = max(t_arr, self._busy_until)
            chunks += self.pump(t_serve)
            if t_serve > self.dev.now():
                self.dev.set(t_serve)
            try:
                reply = self.emu.handle(frame, self.emu.mcu_us(t_serve))
            except Exception:  # noqa: BLE001 - a malformed frame never stops the head (as on its pty)
                self.emu.cnt["framing_errors"] += 1
                reply = None
            self._busy_until = self.dev.now()
            if reply is not None:
                self._up(reply, self.dev.now(), chunks)
        return chunks


class SimLink:
    """A packet link to a :class:`SimHead`: ``send`` returns the send time, ``recv`` the next
    ``(arrival time, packet)`` split at 0x00, waiting in simulated time."""

    def __init__(self, head: SimHead):
        self.head = head
        self.url = head.url
        self.clock = head.lockstep       # its now(): an inline job's own time, else the simulated clock
        self._arrivals: list = []       # heap of (t, n, bytes chunk)
        self._n = 0
        self._buf = bytearray()
        self._ready: list = []          # complete packets (t, bytes) in arrival order
        self.lost: Exception | None = None
        self.overlong = 0
        self.closed = False

    def send(self, data: bytes) -> float:
        if self.closed or self.lost is not None:
            raise LinkLostError(f"sim link {self.url} is down: {self.lost or 'closed'}")
        t = self.clock.now()
        for t_arr, chunk in self.head.transact(bytes(data), t):
            heapq.heappush(self._arrivals, (t_arr, self._n, chunk))
            self._n += 1
        return t

    def _deliver(self, now: float) -> None:
        while self._arrivals and self._arrivals[0][0] <= now:
            t, _, chunk = heapq.heappop(self._arrivals)
            self._buf += chunk
            while True:
                end = self._buf.find(0)
                if end < 0:
                    break
                packet, self._buf = bytes(self._buf[:end]), self._buf[end + 1:]
                if packet:
                    self._ready.append((t, packet))
            if len(self._buf) > 1 << 20:
                self.overlong += 1
                self._buf.clear()

    def _pump(self, now: float) -> None:
        for t_arr, chunk in self.head.pump(now):
            heapq.heappush(self._arrivals, (t_arr, self._n, chunk))
            self._n += 1

    def recv(self, timeout: float):
        now = self.clock.now()
        deadline = now + max(timeout, 0.0)
        while True:
            self._pump(now)
            self._deliver(now)
            if self._ready:
                return self._ready.pop(0)
            if self.lost is not None:
                raise self.lost
            if now >= deadline:
                return None
            # wake at the next arrival, the stream's next step (it may put a frame on the
            # wire) or the deadline, whichever comes first
            nxt = self._arrivals[0][0] if self._arrivals else float("inf")
            self.head.lockstep.wait_until(min(nxt, self.head.next_event(), deadline))
            now = self.clock.now()

    def quiet_until(self) -> float:
        """Simulated time before which :meth:`recv` can return nothing and raise nothing: the
        next chunk's arrival or the head's next stream step (−inf while a packet waits or
        the link is down)."""
        if self._ready or self.lost is not None or self.closed:
            return -float("inf")
        nxt = self._arrivals[0][0] if self._arrivals else float("inf")
        return min(nxt, self.head.next_event())

    def drain(self) -> int:
        self._pump(self.clock.now())
        self._deliver(self.clock.now())
        n = len(self._ready)
        self._ready.clear()
        return n

    def close(self) -> None:
        self.closed = True
