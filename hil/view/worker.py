"""The live view's process: ``python -m gyrostar.hil.view.worker (--save RRD | --connect URL | --spawn)``.

Reads runs of whole log records from stdin, each as ``u32 length`` + bytes (length 0: the end),
decodes them (:class:`.decode.ViewDecoder`) and draws them with rerun (:class:`.rrlog.RerunView`)
into a file, a rerun server or a spawned native viewer. At the end it prints one JSON line of
counts on stdout. It runs niced (a real-time run's view on SCHED_IDLE: ``--idle``), in its own
session (a Ctrl-C at the terminal is the run's).
"""

from __future__ import annotations

import argparse
import json
import os
import struct
import sys

LEN = struct.Struct("<I")
APP_ID = "gyrostar"
SPAWN_PORT = 9876        # rerun's default viewer port


def _read_exact(f, n: int) -> bytes:
    buf = bytearray()
    while len(buf) < n:
        got = f.read(n - len(buf))
        if not got:
            raise EOFError
        buf += got
    return bytes(buf)


def chunks(f):
    """Each run of records sent by :class:`.feed.ViewFeed` (stops at the end mark or EOF)."""
    while True:
        try:
            (n,) = LEN.unpack(_read_exact(f, LEN.size))
            if n == 0:
                return
            yield _read_exact(f, n)
        except EOFError:
            return


def blueprint():
    """The viewer's layout: the sensor with windows and stars beside the attitude's 3σ, the error
    against the truth, the rate and the mode log."""
    import rerun.blueprint as rrb

    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Spatial2DView(origin="/camera", name="camera: windows, centroids, identified stars"),
            rrb.Vertical(
                rrb.TimeSeriesView(origin="/attitude/sigma3_arcsec", name="attitude 3σ (″)"),
                rrb.TimeSeriesView(origin="/truth/error_arcsec", name="error against the truth (″)"),
                rrb.TimeSeriesView(origin="/gyro/rate_dps", name="rate (°/s)"),
                rrb.TextLogView(origin="/loop/mode", name="modes and events"),
            ),
            column_shares=[3, 2],
        ),
        collapse_panels=True,
    )


def open_recording(save: str | None, connect: str | None, spawn: bool, recording_id: str | None = None):
    """The rerun recording stream with the sinks asked for."""
    import rerun as rr

    rec = rr.RecordingStream(APP_ID, recording_id=recording_id)
    sinks = []
    if save:
        sinks.append(rr.FileSink(save))
    if connect:
        sinks.append(rr.GrpcSink(connect))
    if spawn:
        # the native viewer (rerun's own binary; one already listening on the port is reused)
        rr.spawn(port=SPAWN_PORT, connect=False, recording=rec)
        sinks.append(rr.GrpcSink(f"rerun+http://127.0.0.1:{SPAWN_PORT}/proxy"))
    rec.set_sinks(*sinks, default_blueprint=blueprint())
    return rec


def _step_back(idle: bool) -> None:
    """Give the loop's process the CPU first: niced, and with ``idle`` on SCHED_IDLE (a real-time
    run: the view then falls behind on a busy host and the feed drops records for it, rather
    than the view taking CPU time from the loop)."""
    try:
        os.nice(10)
    except OSError:
        pass
    if idle and hasattr(os, "SCHED_IDLE"):
        try:
            os.sched_setscheduler(0, os.SCHED_IDLE, os.sched_param(0))
        except OSError:
            pass


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="gyrostar.hil.view.worker")
    p.add_argument("--save", default=None)
    p.add_argument("--connect", default=None)
    p.add_argument("--spawn", action="store_true")
    p.add_argument("--recording-id", default=None)
    p.add_argument("--tile-every-s", type=float, default=None)
    p.add_argument("--idle", action="store_true",
                   help="run only on CPU time nothing else wants (SCHED_IDLE): a real-time run's view")
    args = p.parse_args(argv)
    _step_back(args.idle)
    from .decode import ViewDecoder, records_in
    from .rrlog import TILE_EVERY_S, RerunView

    rec = open_recording(args.save, args.connect, args.spawn, args.recording_id)
    view = RerunView(rec, tile_every_s=TILE_EVERY_S if args.tile_every_s is None else args.tile_every_s)
    dec = ViewDecoder(view)
    n_records = n_chunks = 0
    for chunk in chunks(sys.stdin.buffer):
        n_chunks += 1
        for r in records_in(chunk):
            n_records += 1
            dec.feed(r)
    view.flush()
    rec.flush()
    rec.disconnect()
    sys.stdout.write(json.dumps({"chunks": n_chunks, "records": n_records, "frames": dec.frames,
                                 "undecodable": dec.undecodable}) + "\n")
    sys.stdout.flush()
    return 0


if __name__ == "__main__":
    sys.exit(main())
