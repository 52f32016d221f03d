"""Recorder crash safety (small version of ``python -m gyrostar.hil.reliability.recorder_kill``):
SIGKILLed recordings open, keep everything flushed, and hold exactly what was written; a
log cut at any byte reads up to its last whole record."""

import random

from gyrostar.hil.reliability.recorder_kill import expected_record, synthetic_runs
from gyrostar.recording import logfile as lf


def test_sigkill_at_random_points(tmp_path):
    r = synthetic_runs(5, seed=5, folder=tmp_path)
    assert r["all_open"] and r["passed"] == 5, r["failures"]
    assert r["records_min"] > 0


def test_log_cut_at_any_byte_reads_its_whole_records(tmp_path):
    path = tmp_path / "full.gslog"
    with lf.LogWriter(path, flush_bytes=1000) as w:
        ends = []
        for i in range(60):
            kind, ch, t_ns, payload = expected_record(i)
            w.append(kind, payload, channel=ch, t_ns=t_ns)
            w.flush()
            ends.append(w.bytes_written)
    data = path.read_bytes()
    rng = random.Random(2)
    for cut in [len(lf.MAGIC)] + [rng.randrange(len(lf.MAGIC), len(data) + 1) for _ in range(150)] + [len(data)]:
        part = tmp_path / "cut.gslog"
        part.write_bytes(data[:cut])
        rep = lf.ReadReport()
        recs = list(lf.read_records(part, rep))
        whole = sum(1 for e in ends if e <= cut)
        assert len(recs) == whole                                   # everything whole is there…
        assert all((r.kind, r.channel, r.t_ns, r.payload) == expected_record(i) for i, r in enumerate(recs))
        assert rep.good_bytes + rep.ignored_tail_bytes == cut       # …and only the torn tail is ignored
