"""Log format, crash safety and record/replay taps."""

import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
from gyrostar.errors import ConfigError, DeviceError
from gyrostar.recording import logfile as lf
from gyrostar.recording import taps


def test_roundtrip_and_truncated_tail(tmp_path):
    path = tmp_path / "a.gslog"
    payloads = [os.urandom(n) for n in (0, 1, 17, 4096)]
    with lf.LogWriter(path) as w:
        w.meta({"k": 1})
        for i, p in enumerate(payloads):
            w.append(lf.RX, p, channel=i, t_ns=1000 * i)
    recs = list(lf.read_records(path))
    assert [r.payload for r in recs[1:]] == payloads
    assert [r.channel for r in recs[1:]] == [0, 1, 2, 3]
    assert lf.read_meta(path) == {"k": 1}
    # cut the file inside the last record: the reader keeps every complete record
    data = path.read_bytes()
    path.write_bytes(data[:-3])
    rep = lf.ReadReport()
    recs = list(lf.read_records(path, rep))
    assert [r.payload for r in recs[1:]] == payloads[:-1]
    assert rep.ignored_tail_bytes == len(data) - 3 - rep.good_bytes > 0
    # a flipped byte in a payload is caught by the CRC, earlier records survive
    path.write_bytes(data[:-10] + bytes([data[-10] ^ 0xFF]) + data[-9:])
    rep = lf.ReadReport()
    assert len(list(lf.read_records(path, rep))) == 4 and "CRC" in rep.tail_reason


def test_not_a_log(tmp_path):
    p = tmp_path / "x"
    p.write_bytes(b"hello world")
    with pytest.raises(ConfigError):
        list(lf.read_records(p))
    with pytest.raises(ConfigError):
        list(lf.read_records(tmp_path / "missing"))


WRITER = r"""
import sys, time
from gyrostar.recording import logfile as lf
w = lf.LogWriter(sys.argv[1], flush_bytes=1 << 30, flush_s=1e9)
i = 0
while True:
    w.append(lf.RX, i.to_bytes(4, "little") * 8, t_ns=i)
    if i % 100 == 99:
        w.flush()
        print(i, flush=True)
    i += 1
"""


def test_sigkill_loses_only_unflushed_tail(tmp_path):
    path = tmp_path / "k.gslog"
    proc = subprocess.Popen([sys.executable, "-c", WRITER, str(path)], stdout=subprocess.PIPE, text=True)
    last = -1
    deadline = time.monotonic() + 30
    while last < 2000 and time.monotonic() < deadline:
        last = int(proc.stdout.readline())
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    recs = list(lf.read_records(path))
    assert len(recs) >= last + 1                       # everything flushed is there
    assert [int.from_bytes(r.payload[:4], "little") for r in recs] == list(range(len(recs)))


class FakeRegs:
    """A register file that NACKs register 0x55."""

    def __init__(self):
        self.mem = bytearray(range(256))

    def read(self, reg, n):
        if reg == 0x55:
            err = DeviceError("NACK at 0x55")
            err.errno = 121
            raise err
        return bytes(self.mem[reg: reg + n])

    def write(self, reg, data):
        self.mem[reg: reg + len(data)] = data

    def describe(self):
        return "fake"


class FakeLink:
    def __init__(self):
        self.t = 0.0
        self.inbox = [b"\x01\x02", None, b"\x03" * 300]

    def send(self, data):
        self.t += 1e-3
        return self.t

    def recv(self, timeout):
        p = self.inbox.pop(0)
        return None if p is None else (self.t + 0.5e-3, p)

    def drain(self):
        return 2


def _session(regs, link, clock):
    out = [clock.now()]
    regs.write(0x10, b"\x03")
    out.append(regs.read(0x0E, 6))
    with pytest.raises(DeviceError) as e:
        regs.read(0x55, 1)
    out.append(e.value.errno)
    out.append(link.send(b"\x05abc"))
    out += [link.recv(0.1), link.recv(0.1), link.recv(0.1), link.drain(), clock.now()]
    return out


class StepClock:
    def __init__(self):
        self.t = 0.1

    def now(self):
        self.t += 0.1 / 3
        return self.t


def test_replay_taps_reproduce_every_answer(tmp_path):
    path = tmp_path / "t.gslog"
    with lf.LogWriter(path) as w:
        clock = taps.RecordingClock(StepClock(), w)
        live = _session(taps.RecordingRegisters(FakeRegs(), w, clock=clock),
                        taps.RecordingLink(FakeLink(), w, clock=clock), clock)
    recs = list(lf.read_records(path))
    regs = taps.ReplayRegisters([r for r in recs if r.kind == lf.BUS])
    link = taps.ReplayLink([r for r in recs if r.channel == lf.CH_HEAD and r.kind in (lf.TX, lf.RX, taps.WAITING)])
    clock = taps.ReplayClock([np.frombuffer(r.payload, "<f8")[0] for r in recs if r.kind == lf.CLOCK])
    again = _session(regs, link, clock)
    assert again == live
    assert regs.remaining() == link.remaining() == clock.remaining() == 0


def test_replay_detects_divergence(tmp_path):
    path = tmp_path / "d.gslog"
    with lf.LogWriter(path) as w:
        regs = taps.RecordingRegisters(FakeRegs(), w)
        regs.write(0x10, b"\x03")
        regs.read(0x02, 6)
    recs = [r for r in lf.read_records(path) if r.kind == lf.BUS]
    replay = taps.ReplayRegisters(recs)
    with pytest.raises(taps.ReplayDivergence):
        replay.write(0x10, b"\x04")
    with pytest.raises(taps.ReplayDivergence):
        replay.read(0x02, 4)
    with pytest.raises(taps.ReplayExhausted):
        replay.read(0x02, 6)


def test_clock_record_packed_in_one_go_is_the_same_bytes(tmp_path):
    """``append_f8`` (a clock reading) writes exactly the record ``append`` writes for the
    same f8 payload: header, payload and CRC."""
    import struct

    a, b = lf.LogWriter(tmp_path / "a.gslog"), lf.LogWriter(tmp_path / "b.gslog")
    for ch, t in ((0, 1.25), (2, 28722.873475111184), (5, -3.5e-9), (0, float("nan")), (1, 0.0)):
        t_ns = int(round(t * 1e9)) if t == t else 0
        a.append(lf.CLOCK, struct.pack("<d", t), ch, t_ns)
        b.append_f8(lf.CLOCK, t, ch, t_ns)
    a.close()
    b.close()
    assert (tmp_path / "a.gslog").read_bytes() == (tmp_path / "b.gslog").read_bytes()
    recs = list(lf.read_records(tmp_path / "b.gslog", lf.ReadReport()))
    assert [r.channel for r in recs] == [0, 2, 5, 0, 1] and all(r.kind == lf.CLOCK for r in recs)


def test_load_log_for_an_export_keeps_the_outputs_and_drops_the_device_records(tmp_path):
    from gyrostar.hil.replay import load_log
    from gyrostar.loop.record import OUTPUT_DTYPE, TRUTH_DTYPE

    path = tmp_path / "b.gslog"
    outs = np.zeros(5, OUTPUT_DTYPE)
    outs["t"] = np.arange(5.0)
    truth = np.zeros(5, TRUTH_DTYPE)
    truth["t"] = np.arange(5.0)
    with lf.LogWriter(path) as w:
        w.meta({"format": "gyrostar flatsat log 1"})
        w.event({"scenario_t0": 0.5})
        for i in range(5):
            w.append(lf.RX, os.urandom(64), channel=1, t_ns=i)       # link bytes, bus reads …
            w.append(lf.OUTPUT, outs[i:i + 1].tobytes(), t_ns=i)
        w.append(lf.TRUTH, truth.tobytes(), t_ns=0)
        w.event({"summary": {}})
    whole, lean = load_log(path), load_log(path, keep_records=False)
    assert len(whole["records"]) == 14 and len(lean["records"]) == 9
    assert {r.kind for r in lean["records"]} == {lf.META, lf.OUTPUT, lf.TRUTH, lf.EVENT}
    assert lean["outputs"].tobytes() == whole["outputs"].tobytes() == outs.tobytes()
    assert lean["truth"].tobytes() == truth.tobytes()
    assert lean["meta"] == whole["meta"] and lean["events"] == whole["events"]
    assert lean["t0"] == 0.5 and lean["complete"] and whole["complete"]


def test_rows_longer_than_a_record_are_split_into_whole_rows_and_read_back_joined(tmp_path, monkeypatch):
    from gyrostar.hil.replay import load_log
    from gyrostar.loop.record import TRUTH_DTYPE

    truth = np.zeros(10, TRUTH_DTYPE)
    truth["t"] = np.arange(10.0)
    truth["q"][:, 3] = 1.0
    monkeypatch.setattr(lf, "MAX_PAYLOAD", 3 * TRUTH_DTYPE.itemsize + 5)   # 3 rows a record at most
    path = tmp_path / "c.gslog"
    with lf.LogWriter(path) as w:
        w.meta({"format": "gyrostar flatsat log 1"})
        with pytest.raises(ValueError, match="exceeds"):
            w.append(lf.TRUTH, truth.tobytes())                            # one record: refused
        assert w.append_rows(lf.TRUTH, truth) == 4                         # 3 + 3 + 3 + 1 rows
        assert w.append_rows(lf.TRUTH, truth[:0]) == 0
    sizes = [len(r.payload) for r in lf.read_records(path) if r.kind == lf.TRUTH]
    assert sizes == [3 * 88, 3 * 88, 3 * 88, 88]
    assert load_log(path)["truth"].tobytes() == truth.tobytes()
