"""The live view (issue 52): ``gyrostar run/replay --view-save`` read back with rerun's dataframe
API and compared with the run's own log; the terminal panel under a pseudo-terminal; the
view's bad inputs (no rerun-sdk: exit 4, one line)."""

import json
import os
import pty
import select
import subprocess
import time

import numpy as np
import pytest
from cli_helpers import GYROSTAR, gyrostar

rerun = pytest.importorskip("rerun", reason="the live view needs rerun-sdk (the 'view' extra; 'dev' has it)")
pytest.importorskip("datafusion", reason="reading a recording back needs rerun-sdk[catalog] (the 'dev' extra)")

# each test runs gyrostar (a fast 10 s run and its replay take about a minute on an idle host)
pytestmark = pytest.mark.timeout(1800)

ENTITIES = {"/camera", "/camera/windows", "/camera/centroids", "/camera/stars", "/camera/trajectories",
            "/camera/spots", "/attitude/q", "/attitude/rpy_deg", "/attitude/sigma3_arcsec", "/gyro/rate_dps",
            "/gyro/bias_dps", "/loop/mode", "/loop/stars", "/loop/latency_us", "/loop/overruns", "/loop/gyro_gaps",
            "/link/bytes_per_s", "/link/utilisation", "/truth/q", "/truth/error_arcsec"}


@pytest.fixture(scope="module")
def viewed(tmp_path_factory):
    """One fast 10 s run with --view-save, and the replay of its log with --view-save."""
    d = tmp_path_factory.mktemp("view")
    run = gyrostar(["run", "--fast", "--duration", "10", "--view-save", d / "R.rrd", "--no-plots", "--out", d / "run",
                    "--json"], timeout=1800)
    assert run.returncode == 0, run.stderr[-2000:]
    rep = gyrostar(["replay", d / "run" / "flatsat.gslog", "--view-save", d / "R2.rrd", "--json"], timeout=1800)
    assert rep.returncode == 0, rep.stderr[-2000:]
    return d, json.loads(run.stdout), json.loads(rep.stdout)


def _log(d):
    from gyrostar.hil.replay import load_log

    return load_log(d / "run" / "flatsat.gslog")


def _frames_used(log) -> np.ndarray:
    """Mid-exposure times of the frames the loop was handed (the streaming port's poll answers)."""
    from gyrostar.hil.headport import POLL
    from gyrostar.hil.streamport import CH_STREAM_POLL, unpack_result

    t = []
    for r in log["records"]:
        if r.kind == POLL and r.channel == CH_STREAM_POLL and r.payload[:1] == b"\x01":
            res = unpack_result(r.payload)
            if res.kind == "windows" and res.error is None:
                t.append(res.t_mid)
    return np.array(t)


def _scalars(df, entity):
    return np.stack(df[f"{entity}:Scalars:scalars"].to_numpy())


def test_run_recording_holds_the_entities_frames_attitudes_and_labels(viewed):
    from gyrostar.hil.view.names import star_label
    from gyrostar.hil.view.read import entities, entity_table, load
    from gyrostar.loop.record import FLAG_UPDATE_APPLIED

    d, summary, _ = viewed
    log = _log(d)
    out = log["outputs"]
    st = load(d / "R.rrd")
    assert ENTITIES <= entities(st), ENTITIES - entities(st)
    assert summary["view"]["dropped_chunks"] == 0 and summary["view"]["frames"] == summary["frames"]

    # one windows entry per frame the loop used, at its mid-exposure
    used = _frames_used(log)
    win = entity_table(st, "/camera/windows")
    assert len(used) == summary["frames"] and len(win) == len(used)
    np.testing.assert_allclose(win["time"].to_numpy(), np.sort(used), atol=1e-6)

    # one attitude sample per output, the output's quaternion at the output's time
    att = entity_table(st, "/attitude/q")
    assert len(att) == len(out)
    np.testing.assert_allclose(att["time"].to_numpy(), out["t"], atol=1e-6)
    np.testing.assert_allclose(_scalars(att, "/attitude/q"), out["q"], atol=1e-12)

    # identified-star labels: the log's identifications at each output that applied a frame
    upd = out[(out["flags"] & FLAG_UPDATE_APPLIED) != 0]
    stars = entity_table(st, "/camera/stars")
    assert len(stars) == len(upd) > 0.9 * summary["frames"]
    np.testing.assert_allclose(stars["time"].to_numpy(), upd["t"], atol=1e-6)
    named = 0
    for labels, rec in zip(stars["/camera/stars:Points2D:labels"], upd, strict=True):
        want = [star_label(int(s)) for s in rec["star_id"][: rec["n_stars"]]]
        assert list(labels) == want
        named += sum(lab.startswith("HIP ") for lab in labels)
    assert named > 5 * len(upd)      # the demo tracks ~12 identified stars

    # the truth and the error against it (simulation): small while tracking, like the run's figure
    err = _scalars(entity_table(st, "/truth/error_arcsec"), "/truth/error_arcsec")
    cross = np.sqrt(np.mean(err[len(err) // 2:, :2] ** 2))
    assert cross < 3 * summary["attitude_error_arcsec_1sigma"] + 1.0


def test_replay_recording_holds_the_same_frames_and_attitudes(viewed):
    from gyrostar.hil.view.read import entity_table, load

    d, summary, rep = viewed
    assert rep["verdict"] == "bit-exact" and rep["view"]["frames"] == summary["frames"]
    a, b = load(d / "R.rrd"), load(d / "R2.rrd")
    for entity in ("/camera/windows", "/camera/stars"):
        ta, tb = entity_table(a, entity)["time"].to_numpy(), entity_table(b, entity)["time"].to_numpy()
        assert len(ta) == len(tb) > 0
        np.testing.assert_array_equal(ta, tb)
    qa, qb = entity_table(a, "/attitude/q"), entity_table(b, "/attitude/q")
    np.testing.assert_array_equal(qa["time"].to_numpy(), qb["time"].to_numpy())
    np.testing.assert_array_equal(_scalars(qa, "/attitude/q"), _scalars(qb, "/attitude/q"))


def _under_pty(argv, timeout=900.0, stdout_pipe=False):
    """Run gyrostar with stderr (and stdout unless ``stdout_pipe``) on a pseudo-terminal; return
    (exit code, what the terminal got, stdout when piped)."""
    master, slave = pty.openpty()
    proc = subprocess.Popen([GYROSTAR, *map(str, argv)], stdin=subprocess.DEVNULL, stderr=slave,
                            stdout=subprocess.PIPE if stdout_pipe else slave, env=dict(os.environ, COLUMNS="120",
                                                                                         LINES="40"))
    os.close(slave)
    got = bytearray()
    deadline = time.monotonic() + timeout
    try:
        while time.monotonic() < deadline:
            r, _, _ = select.select([master], [], [], 0.5)
            if r:
                try:
                    chunk = os.read(master, 65536)
                except OSError:      # the other side closed
                    break
                if not chunk:
                    break
                got += chunk
            elif proc.poll() is not None:
                break
        out = proc.stdout.read().decode() if stdout_pipe else ""
        proc.wait(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        os.close(master)
    return proc.returncode, got.decode(errors="replace"), out


def test_panel_renders_on_a_terminal_with_its_fields(tmp_path):
    code, term, _ = _under_pty(["run", "--fast", "--duration", "4", "--no-plots", "--out", tmp_path / "r"])
    assert code == 0, term[-2000:]
    for field in ("gyrostar run", "mode", "TRACK", "for", "stars", "tracked", "identified", "rate", "°/s",
                  "attitude 1σ", "covariance", "error", "simulator truth", "frames", "Hz", "exposure → output",
                  "link", "% used", "overruns", "samples lost", "time", "s left"):
        assert field in term, field
    assert "╭" in term or "┌" in term        # a panel, not the one status line


def test_json_on_a_terminal_keeps_stdout_one_object_and_no_panel(tmp_path):
    code, term, out = _under_pty(["run", "--fast", "--duration", "2", "--no-plots", "--out", tmp_path / "r",
                                  "--json"], stdout_pipe=True)
    assert code == 0, term[-2000:]
    obj = json.loads(out)
    assert obj["exit_code"] == 0 and obj["frames"] > 0
    assert "attitude 1σ" not in term and "s left" not in term


def test_view_without_rerun_exits_4_with_one_line(tmp_path):
    """rerun-sdk not importable (shadowed by a package that fails to import, as a missing one does)."""
    shadow = tmp_path / "shadow" / "rerun"
    shadow.mkdir(parents=True)
    (shadow / "__init__.py").write_text("raise ImportError(\"No module named 'rerun'\")\n")
    env = {"PYTHONPATH": str(tmp_path / "shadow"), "GYROSTAR_RUNS": str(tmp_path / "runs")}
    for argv in (["run", "--fast", "--duration", "1", "--view"], ["run", "--view-save", tmp_path / "x.rrd"],
                 ["run", "--view-serve"], ["replay", "nope.gslog", "--view-save", tmp_path / "x.rrd"]):
        res = gyrostar(argv, env=env, timeout=120)
        lines = [ln for ln in res.stderr.splitlines() if ln.strip()]
        assert res.returncode == 4 and len(lines) == 1 and "rerun-sdk" in lines[0] and "view" in lines[0], \
            (argv, res.returncode, res.stderr)
        assert "Traceback" not in res.stderr
    assert not (tmp_path / "runs").exists()


def test_native_viewer_without_a_display_exits_4(tmp_path):
    res = gyrostar(["run", "--fast", "--duration", "1", "--view"],
                   env={"DISPLAY": "", "WAYLAND_DISPLAY": "", "GYROSTAR_RUNS": str(tmp_path / "runs")})
    lines = [ln for ln in res.stderr.splitlines() if ln.strip()]
    assert res.returncode == 4 and len(lines) == 1 and "display" in lines[0], res.stderr
    assert not (tmp_path / "runs").exists()


def test_feed_in_real_time_drops_for_the_view_when_full_and_never_waits():
    """The writer thread's hand-over: a full queue drops the run of records (counted), no wait."""
    from gyrostar.hil.view.feed import QUEUE_CHUNKS, ViewFeed, ViewOptions

    feed = ViewFeed(ViewOptions(save="unused.rrd"), lossless=False)     # not started: nobody drains it
    for i in range(QUEUE_CHUNKS + 5):
        feed.tee(b"x" * (i + 1))
    assert feed.chunks == QUEUE_CHUNKS and feed.dropped_chunks == 5
    assert feed.dropped_bytes == sum(range(QUEUE_CHUNKS + 1, QUEUE_CHUNKS + 6))


def test_records_cross_the_pipe_as_the_log_holds_them(tmp_path):
    """A run of records as the view gets it decodes to the records the log file holds."""
    from gyrostar.hil.view.decode import records_in
    from gyrostar.hil.view.feed import record_bytes
    from gyrostar.recording import logfile as lf

    recs = [lf.Record(lf.OUTPUT, 0, 5, b"\x01" * 100), lf.Record(lf.TX, lf.CH_HEAD, 7, b"abc"),
            lf.Record(lf.EVENT, 0, 9, b'{"x": 1}')]
    with lf.LogWriter(tmp_path / "a.gslog") as w:
        for r in recs:
            w.append(r.kind, r.payload, r.channel, r.t_ns)
    chunk = b"".join(record_bytes(r.kind, r.payload, r.channel, r.t_ns) for r in recs)
    assert (tmp_path / "a.gslog").read_bytes() == lf.MAGIC + chunk
    assert list(records_in(chunk)) == recs == list(lf.read_records(tmp_path / "a.gslog"))


def test_web_viewer_server_listens_on_loopback_only_and_stops_whole():
    """--view-serve's server: both ports on 127.0.0.1 (not on the wildcard address), and after
    close() nothing listens any more (the launcher's server child stopped with it)."""
    import socket

    from gyrostar.hil.view.feed import ViewServer, free_port

    srv = ViewServer(free_port()).start()
    try:
        listening = subprocess.run(["ss", "-Hltn"], capture_output=True, text=True).stdout
        for port in (srv.web_port, srv.grpc_port):
            where = [ln.split()[3] for ln in listening.splitlines() if ln.split()[3].endswith(f":{port}")]
            assert where == [f"127.0.0.1:{port}"], (port, where)
        assert srv.viewer_url.startswith(f"http://127.0.0.1:{srv.web_port}/?url=rerun%2Bhttp")
    finally:
        srv.close()
    for port in (srv.web_port, srv.grpc_port):
        with pytest.raises(OSError):
            socket.create_connection(("127.0.0.1", port), timeout=1.0).close()
