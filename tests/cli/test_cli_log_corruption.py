"""A flipped byte or a torn write in a flatsat log: the reader resyncs to the next intact
record and says where and how much it skipped; ``replay --check`` fails loudly on it; a
log cut short is reported as a prefix. Offsets are checked against the record layout
computed independently while writing."""

import json
import struct

import pytest
from cli_helpers import gyrostar
from gyrostar.recording import logfile as lf

HEAD, CRC = 16, 4


def _write(path, payloads):
    """A log of RX records; returns each record's (offset, size) from the format's layout."""
    spans, pos = [], len(lf.MAGIC)
    with lf.LogWriter(path) as w:
        for i, p in enumerate(payloads):
            w.append(lf.RX, p, channel=i % 3, t_ns=i)
            spans.append((pos, HEAD + len(p) + CRC))
            pos += HEAD + len(p) + CRC
    return spans


def _flip(path, offset):
    data = bytearray(path.read_bytes())
    data[offset] ^= 0x5A
    path.write_bytes(bytes(data))


PAYLOADS = [bytes([0xA5, i]) * (7 * i + 3) for i in range(20)]   # sync bytes inside payloads too


@pytest.mark.parametrize("where", ["payload", "sync", "length", "crc"])
def test_one_corrupt_record_is_skipped_and_reported(tmp_path, where):
    path = tmp_path / "a.gslog"
    spans = _write(path, PAYLOADS)
    k = 7
    off, size = spans[k]
    _flip(path, off + {"payload": HEAD + 5, "sync": 0, "length": 4, "crc": size - 2}[where])
    rep = lf.ReadReport()
    got = list(lf.read_records(path, rep))
    assert [r.payload for r in got] == PAYLOADS[:k] + PAYLOADS[k + 1:]
    assert [(o, n) for o, n, _ in rep.skipped] == [(off, size)]
    assert rep.skipped_bytes == size and rep.ignored_tail_bytes == 0
    assert f"at byte {off}" in rep.describe()


def test_two_corruptions_and_a_torn_tail(tmp_path):
    path = tmp_path / "b.gslog"
    spans = _write(path, PAYLOADS)
    for k in (3, 4, 12):                 # two neighbours are one stretch, then another
        _flip(path, spans[k][0] + HEAD + 1)
    cut = spans[-1][0] + 9               # inside the last record's header
    path.write_bytes(path.read_bytes()[:cut])
    rep = lf.ReadReport()
    got = [r.payload for r in lf.read_records(path, rep)]
    assert got == [p for i, p in enumerate(PAYLOADS[:-1]) if i not in (3, 4, 12)]
    assert [(o, n) for o, n, _ in rep.skipped] == [(spans[3][0], spans[3][1] + spans[4][1]), spans[12]]
    assert rep.ignored_tail_bytes == 9 and rep.good_bytes == spans[-1][0]


@pytest.fixture(scope="module")
def run_log(tmp_path_factory):
    out = tmp_path_factory.mktemp("run") / "r"
    res = gyrostar(["run", "--fast", "--duration", "2", "--no-plots", "-q", "--out", out])
    assert res.returncode == 0, res.stderr
    return out / "flatsat.gslog"


def _record_spans(data):
    """(offset, size, kind) of every record, walking the layout with struct (not the reader)."""
    pos, out = len(lf.MAGIC), []
    while pos < len(data):
        sync, kind, _ch, length, _t = struct.unpack_from("<BBHIq", data, pos)
        assert sync == 0xA5
        out.append((pos, HEAD + length + CRC, kind))
        pos += HEAD + length + CRC
    return out


def _replay(path, *extra):
    res = gyrostar(["replay", path, "--check", "--json", *extra])
    assert "Traceback" not in res.stderr
    return res, json.loads(res.stdout)


def test_replay_check_intact_log(run_log):
    res, obj = _replay(run_log)
    assert res.returncode == 0 and obj["verdict"] == "bit-exact" and obj["log_skipped_bytes"] == 0


def test_replay_check_fails_loudly_on_a_flipped_byte(run_log, tmp_path):
    data = bytearray(run_log.read_bytes())
    outputs = [s for s in _record_spans(data) if s[2] == lf.OUTPUT]
    off, size, _ = outputs[len(outputs) // 2]
    data[off + HEAD + 40] ^= 0x01
    bad = tmp_path / "flipped.gslog"
    bad.write_bytes(bytes(data))
    res, obj = _replay(bad)
    assert res.returncode == 1, res.stderr
    assert obj["verdict"] == "corrupt" and not obj["bit_exact"]
    assert obj["log_skipped"] == [{"offset": off, "bytes": size, "reason": f"CRC mismatch at byte {off}"}]
    assert obj["recorded_outputs"] > 0
    assert "CORRUPT LOG" in res.stderr and f"byte {off}" in res.stderr     # the human line (stderr with --json)


def test_replay_check_reports_a_cut_log_as_a_prefix(run_log, tmp_path):
    data = run_log.read_bytes()
    spans = _record_spans(data)
    cut_rec = spans[len(spans) * 2 // 3]
    cut = tmp_path / "cut.gslog"
    cut.write_bytes(data[: cut_rec[0] + 11])            # a crash tore this record's header
    res, obj = _replay(cut)
    assert res.returncode == 0, res.stderr
    assert obj["verdict"] == "prefix" and obj["prefix_exact"] and not obj["log_complete"]
    assert obj["compared_outputs"] == obj["recorded_outputs"] > 0
    assert obj["log_tail_ignored_bytes"] == 11 and obj["first_difference_at"] is None
    assert "PREFIX" in res.stderr and "None" not in res.stderr


def test_heavily_corrupt_log_gives_a_verdict_not_an_error(run_log, tmp_path):
    """Every 4th record of the log's second half flipped: the loop's replay loses link frames
    it needs and diverges from the log. The replay stops there with the CORRUPT verdict
    (exit 0; 1 with --check), no error; an export says it holds the intact records only."""
    data = bytearray(run_log.read_bytes())
    spans = _record_spans(data)
    for off, size, _ in spans[len(spans) // 2::4]:
        data[off + HEAD + (size - HEAD - CRC) // 2] ^= 0x10
    bad = tmp_path / "heavy.gslog"
    bad.write_bytes(bytes(data))
    res, obj = _replay(bad)
    assert res.returncode == 1, res.stderr
    assert obj["verdict"] == "corrupt" and obj["stopped"].startswith("diverged from the log")
    assert len(obj["log_skipped"]) >= len(spans[len(spans) // 2::4]) // 2
    plain = gyrostar(["replay", bad])
    assert plain.returncode == 0 and "Traceback" not in plain.stderr, plain.stderr
    assert "CORRUPT LOG" in plain.stdout + plain.stderr and "replay stopped" in plain.stdout + plain.stderr
    exp = gyrostar(["replay", bad, "--export", "csv", "--out", tmp_path / "h.csv"])
    assert exp.returncode == 0, exp.stderr
    assert "the export holds the intact records only" in exp.stdout + exp.stderr


@pytest.mark.parametrize("fmt", ["csv", "calib"])
def test_export_of_a_cut_log_says_it_is_cut(run_log, tmp_path, fmt):
    """A log torn mid-record by a crash (no closing summary, a torn last record): the export
    writes what was recorded and its line says the log was cut short and how many bytes of the
    torn record it ignored; the same for a flipped byte in the calibration export."""
    data = run_log.read_bytes()
    spans = _record_spans(data)
    cut_rec = spans[len(spans) * 2 // 3]
    cut = tmp_path / "cut.gslog"
    cut.write_bytes(data[: cut_rec[0] + 11])
    out = tmp_path / f"cut.{'npz' if fmt == 'calib' else fmt}"
    res = gyrostar(["replay", cut, "--export", fmt, "--out", out, "--json"])
    assert res.returncode == 0 and "Traceback" not in res.stderr, res.stderr
    obj = json.loads(res.stdout)
    assert obj["log_tail_ignored_bytes"] == 11 and obj["log_complete"] is False and obj["log_skipped_bytes"] == 0
    assert "11 bytes of a torn record" in res.stderr and "no closing summary" in res.stderr
    assert out.exists()
    whole = gyrostar(["replay", run_log, "--export", fmt, "--out", tmp_path / f"whole.{out.suffix[1:]}", "--json"])
    wobj = json.loads(whole.stdout)
    assert wobj["log_complete"] is True and wobj["log_tail_ignored_bytes"] == 0
    assert "torn" not in whole.stderr and "summary" not in whole.stderr
    if fmt == "calib":
        flipped = bytearray(data)
        outputs = [s for s in spans if s[2] == lf.OUTPUT]
        off, size, _ = outputs[len(outputs) // 2]
        flipped[off + HEAD + 40] ^= 0x01
        bad = tmp_path / "flipped.gslog"
        bad.write_bytes(bytes(flipped))
        res = gyrostar(["replay", bad, "--export", "calib", "--out", tmp_path / "flipped.npz"])
        assert res.returncode == 0 and "Traceback" not in res.stderr, res.stderr
        assert f"CORRUPT LOG: {size} bytes skipped in 1 place(s)" in res.stdout + res.stderr
