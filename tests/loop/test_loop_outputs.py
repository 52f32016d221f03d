"""Output record layout, UDP stream, scheduler, flatsat config."""

import os
import socket
import threading

import numpy as np
import pytest
from gyrostar.errors import ConfigError
from gyrostar.hil import config as hc
from gyrostar.loop import record, sinks
from gyrostar.loop.scheduler import PeriodicScheduler, realtime_setup
from gyrostar.realtime import join_realtime, leave_realtime


def test_record_layout_is_fixed_little_endian():
    dt = record.OUTPUT_DTYPE
    assert dt.itemsize == 8 + 4 + 1 + 1 + 2 + 32 + 24 + 24 + 288 + 64 + 128 + 4 + 2 * (8 + 32 + 72) == 804
    assert dt.fields["q"][1] == 16 and dt.fields["cov"][1] == 96
    r = record.empty(2)
    assert (r["star_id"] == -1).all()
    assert record.flag_names(record.FLAG_ATTITUDE_VALID | record.FLAG_GYRO_GAP) == ["attitude_valid", "gyro_gap"]


def _numbered(n: int):
    recs = record.empty(n)
    recs["t"] = np.arange(n, dtype=float)
    recs["cov"] = np.arange(n, dtype=float)[:, None, None] * np.ones((6, 6))
    return recs


def test_array_sink_reserve_keeps_page_touching_and_growth_out_of_put():
    recs = _numbered(40)
    sink = sinks.ArraySink(capacity=30, chunk_rows=4)    # sized for the run: 4 rows touched
    sink.put(recs[:3])
    sink.put(recs[3:9])                                  # past the touched rows: this put touches
    assert sink.touched_in_put == 5 and sink.grown_in_put == 0
    for a, b in ((9, 10), (10, 13), (13, 13), (13, 17), (17, 21), (21, 25)):
        sink.reserve()                                   # between steps: the next rows' pages
        sink.put(recs[a:b])
    assert sink.touched_in_put == 5                      # no put touched memory after a reserve
    kept = sink.records
    assert len(kept) == 25 and kept.dtype == record.OUTPUT_DTYPE
    assert kept.tobytes() == recs[:25].tobytes()
    sink.put(recs[25:40])                                # more than the capacity: the put grows it
    assert sink.grown_in_put == 1
    assert sink.records.tobytes() == recs.tobytes()
    assert (sink.records["t"] == np.arange(40)).all()
    assert len(sinks.ArraySink(capacity=3).records) == 0


def test_array_sink_keeps_every_record_across_growth():
    rng = np.random.default_rng(3)
    recs = record.empty(37)
    recs["t"] = rng.normal(size=37)
    recs["q"] = rng.normal(size=(37, 4))
    recs["star_id"][:, :3] = rng.integers(0, 9000, size=(37, 3))
    recs["cov"] = rng.normal(size=(37, 6, 6))
    sink = sinks.ArraySink(capacity=5)              # grows several times
    for a, b in ((0, 1), (1, 4), (4, 4), (4, 20), (20, 37)):
        sink.put(recs[a:b])
    kept = sink.records
    assert len(kept) == 37 and kept.dtype == record.OUTPUT_DTYPE
    assert kept.tobytes() == recs.tobytes()           # bit for bit, every field
    assert kept[-1]["star_id"][0] == recs[-1]["star_id"][0]


def test_udp_stream_roundtrip_on_loopback():
    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rx.bind(("127.0.0.1", 0))
    rx.settimeout(2.0)
    sink = sinks.UdpSink("127.0.0.1", rx.getsockname()[1])
    n = 2 * sinks.UDP_MAX_RECORDS + 12            # > one datagram's worth: split (3 fit the socket buffer)
    recs = record.empty(n)
    recs["seq"] = np.arange(n)
    recs["q"][:, 3] = 1.0
    sink.put(recs)
    got = []
    while sum(len(g) for g in got) < n:
        got.append(sinks.decode_datagram(rx.recv(65535)))
    assert len(got) == 3 and len(got[0]) == sinks.UDP_MAX_RECORDS
    back = np.concatenate(got)
    assert back.tobytes() == recs.tobytes()
    sink.close()
    rx.close()


def test_udp_refuses_remote_and_bad_datagrams():
    with pytest.raises(ConfigError):
        sinks.UdpSink("10.0.0.1", 5000)
    with pytest.raises(ConfigError):
        sinks.decode_datagram(b"GYS1\x00\x00")
    with pytest.raises(ConfigError):
        sinks.decode_datagram(b"XXXX" + bytes(4))


def test_udp_host_resolved_once_never_in_the_loop(monkeypatch):
    """A host name is looked up when the sink opens, never per datagram (``sendto`` with a name
    resolved it every time inside the loop thread: 158 gyro samples of 2,000 and 2,038 overruns
    for a name that does not resolve); one that does not resolve names its config key."""
    from gyrostar.telemetry import packets, timescale

    lookups = []
    real = socket.getaddrinfo

    def counting(*a, **k):
        lookups.append(a[0])
        return real(*a, **k)

    monkeypatch.setattr(socket, "getaddrinfo", counting)
    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rx.bind(("127.0.0.1", 0))
    rx.settimeout(2.0)
    sink = sinks.UdpSink("localhost", rx.getsockname()[1])
    tm = packets.SpacePacketSink("localhost", 9, timescale.capture())
    recs = record.empty(3)
    for _ in range(20):
        sink.put(recs)
        tm.put(recs)
    assert lookups == ["localhost", "localhost"] and sink.addr == ("127.0.0.1", rx.getsockname()[1])
    assert len(sinks.decode_datagram(rx.recv(65535))) == 3 and sink.sent == 60
    sink.close()
    tm.close()
    rx.close()
    with pytest.raises(ConfigError, match=r"outputs\.udp_host = 'no\.such\.host\.invalid' does not resolve"):
        sinks.UdpSink("no.such.host.invalid", 5000, allow_remote=True)
    with pytest.raises(ConfigError, match=r"outputs\.tm_host"):
        packets.SpacePacketSink("no.such.host.invalid", 5000, timescale.capture(), allow_remote=True)


class FakeTime:
    def __init__(self):
        self.t = 100.0

    def now(self):
        return self.t

    def sleep(self, dt):
        self.t += dt


def test_scheduler_is_drift_free_and_counts_overruns():
    ft = FakeTime()
    s = PeriodicScheduler(0.0025, clock=ft.now, sleep=ft.sleep, spin_s=0.0)
    s.start()
    wakes = []
    for k in range(400):
        wakes.append(s.wait())
        ft.t += 0.0011 if k != 100 else 0.0080     # one step takes 8 ms: misses 3 deadlines
        s.done()
    assert s.overruns == 3
    # one overrun event, at the first missed deadline: step 101's (t0 + 101·T)
    assert len(s.overrun_t) == 1 and abs(s.overrun_t[0] - (100.0 + 101 * 0.0025)) < 1e-9
    wakes = np.array(wakes) - 100.0
    # every wake-up is on the grid t0 + k·period: no accumulated drift
    k = np.round(wakes / 0.0025)
    assert np.max(np.abs(wakes - k * 0.0025)) < 1e-9
    assert k[-1] == 399 + 3


def test_realtime_setup_reports_instead_of_failing():
    # Linux applies policy and affinity to the calling thread (and threads it starts later):
    # run it in a throw-away thread so the test process is never left SCHED_FIFO on one CPU
    # (a FIFO thread spinning there starves every other thread pinned beside it).
    seen = {}

    def probe():
        st = realtime_setup(priority=10, cpus=[0])
        seen["st"] = st
        seen["policy"] = os.sched_getscheduler(0) & ~getattr(os, "SCHED_RESET_ON_FORK", 0)
        seen["cpus"] = os.sched_getaffinity(0)
        seen["workers_join"] = join_realtime() == st.sched_fifo
        leave_realtime()
        seen["left"] = os.sched_getscheduler(0) == os.SCHED_OTHER and not join_realtime()

    t = threading.Thread(target=probe)
    t.start()
    t.join()
    st = seen["st"]
    assert st.sched_fifo == (seen["policy"] == os.SCHED_FIFO)
    assert st.sched_fifo or any("SCHED_FIFO" in n for n in st.notes)
    assert st.cpus == [0] == sorted(seen["cpus"]) or any("affinity" in n for n in st.notes)
    assert os.sched_getscheduler(0) == os.SCHED_OTHER
    assert seen["workers_join"] and seen["left"]


def test_flatsat_config_and_scenarios_validate(tmp_path):
    cfg = hc.load_flatsat()
    assert cfg.simulated and cfg.gyro.odr_hz == 400
    names = hc.scenario_names()
    for need in ("demo", "sim1", "sim2", "sim3", "sim4", "slew10", "eclipse", "disconnect",
                 "fifo_overrun", "corruption"):
        assert need in names
        hc.load_scenario(need)
    bad = tmp_path / "bad.toml"
    bad.write_text('[gyro]\nkind = "usb"\n')
    with pytest.raises(ConfigError, match="gyro.kind"):
        hc.load_flatsat(bad)
    bad.write_text('[head]\nkind = "serial"\n')
    with pytest.raises(ConfigError, match="head.url"):
        hc.load_flatsat(bad)
    with pytest.raises(ConfigError, match="unknown scenario"):
        hc.load_scenario("nope")


def test_output_stage_hands_blocks_to_keeping_sinks_and_batches_to_the_rest():
    from gyrostar.clock import SimulatedClock
    from gyrostar.loop.outputs import OutputStage

    class Now:
        def __init__(self):
            self.got = []

        def put(self, recs, t_ns):
            self.got.append((recs.copy(), t_ns))

    class Keep(Now):
        block = True

    now, keep, arr = Now(), Keep(), sinks.ArraySink(capacity=4)
    stage = OutputStage([now, keep, arr], SimulatedClock(0.0), capacity=16, block_rows=5)
    rng = np.random.default_rng(7)
    sizes = [1, 1, 2, 3, 1, 2, 14, 16, 1, 1]      # 14 does not fit behind the 3 pending
    t, seq = 0.0, 0
    for n in sizes:
        out = stage.batch(n)
        assert len(out) == n
        out["seq"] = np.arange(seq, seq + n)
        out["q"] = rng.normal(size=(n, 4))
        seq += n
        t += 0.0025 * n
        stage.emit(out, 0.0, t)
        assert stage.last["seq"] == seq - 1
        assert [len(r) for r, _ in now.got][-1] == n          # waiting sinks: every batch at once
    assert sum(len(r) for r, _ in keep.got) < seq             # the tail is still pending
    stage.flush()
    sent = np.concatenate([r for r, _ in now.got])
    kept = np.concatenate([r for r, _ in keep.got])
    assert kept.tobytes() == sent.tobytes() == arr.records.tobytes()
    assert (kept["seq"] == np.arange(seq)).all()
    # a block closes at block_rows or more, early before a batch that would not fit, and at the flush
    assert [len(r) for r, _ in keep.got] == [7, 3, 14, 16, 2]
    assert keep.got[-1][1] == int(t * 1e9)                    # stamped with its last sample's time
    stage.flush()                                             # nothing pending: nothing sent
    assert len(keep.got) == 5
