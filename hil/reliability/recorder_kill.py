"""Recorder crash safety: SIGKILL a recording process at random points, then read the log.

``python -m gyrostar.hil.reliability.recorder_kill [--runs 100] [--flatsat-runs 5] [--seed 1]``

* ``--runs``: a child process records deterministic records (random kinds, channels and
  payload sizes 0–20 kB, content a function of the record number) through
  :class:`~gyrostar.recording.logfile.LogWriter` with its automatic flushing, plus explicit
  ``flush()`` calls at random points; after each one it stores the number of records
  flushed in a side file (one 8-byte ``pwrite``). The parent kills it with SIGKILL after a
  random 0.05–1.5 s. Checks: the log opens (magic, no exception), every record up to the
  last reported flush is there, every readable record is exactly the one written (kind,
  channel, time, payload), and only the torn tail (if any) is ignored.
* ``--flatsat-runs``: ``gyrostar run`` on the built-in flatsat killed at a random time;
  the log opens, its readable part replays bit-exactly through the driver and loop
  (``gyrostar replay``: replayed outputs equal the recorded ones as far as they go), and
  the last recorded output is at most the writer's flush interval plus the output stage's
  block (:data:`gyrostar.loop.outputs.BLOCK_ROWS` samples) and one loop step older than
  the kill (0.25 s of margin for the host).

Prints one JSON object; exit status 1 on any failure.
"""

from __future__ import annotations

import argparse
import json
import os
import random
import signal
import struct
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

COUNT = struct.Struct("<q")


def expected_record(i: int) -> tuple[int, int, int, bytes]:
    """(kind, channel, t_ns, payload) of record ``i`` (deterministic)."""
    r = random.Random(i)
    n = r.choice([0, 1, 7, 64, 500, 4096, r.randrange(20000)])
    return r.randrange(1, 10), r.randrange(4), i * 1_000_003 - 7, r.randbytes(n)


def child(log: str, side: str, seed: int) -> None:
    """Record forever; after every explicit flush store the flushed count in ``side``."""
    from ...recording.logfile import LogWriter

    rng = random.Random(seed)
    fd = os.open(side, os.O_WRONLY | os.O_CREAT, 0o644)
    w = LogWriter(log, flush_bytes=rng.choice([4096, 65536, 1 << 20]), flush_s=rng.choice([0.01, 0.05, 1.0]),
                  background=rng.random() < 0.5)
    i = 0
    while True:
        kind, ch, t_ns, payload = expected_record(i)
        w.append(kind, payload, channel=ch, t_ns=t_ns)
        i += 1
        if rng.random() < 0.02:
            w.flush()
            os.pwrite(fd, COUNT.pack(i), 0)


def check_synthetic_log(log: Path, side: Path) -> dict:
    from ...recording import logfile as lf

    flushed = COUNT.unpack(side.read_bytes()[:8])[0] if side.exists() and side.stat().st_size >= 8 else 0
    rep = lf.ReadReport()
    try:
        recs = list(lf.read_records(log, rep))
    except Exception as exc:  # noqa: BLE001 - any failure to open is the finding
        return {"opens": False, "error": repr(exc), "flushed": flushed}
    exact = all((r.kind, r.channel, r.t_ns, r.payload) == expected_record(i) for i, r in enumerate(recs))
    return {"opens": True, "records": len(recs), "flushed": flushed, "all_flushed_present": len(recs) >= flushed,
            "exact": exact, "ignored_tail_bytes": rep.ignored_tail_bytes, "tail_reason": rep.tail_reason,
            "ok": len(recs) >= flushed and exact}


def synthetic_runs(runs: int, seed: int, folder: Path) -> dict:
    rng = random.Random(seed)
    results = []
    for k in range(runs):
        log, side = folder / f"kill{k}.gslog", folder / f"kill{k}.count"
        p = subprocess.Popen([sys.executable, "-m", "gyrostar.hil.reliability.recorder_kill", "--child", str(log),
                              str(side), str(seed * 1000 + k)])
        # wait until the child has created its log (interpreter start-up), then a random delay
        t_end = time.monotonic() + 30.0
        while not log.exists() and time.monotonic() < t_end and p.poll() is None:
            time.sleep(0.01)
        time.sleep(rng.uniform(0.05, 1.5))
        p.send_signal(signal.SIGKILL)
        p.wait()
        res = check_synthetic_log(log, side)
        res["run"] = k
        results.append(res)
        log.unlink(missing_ok=True)
        side.unlink(missing_ok=True)
    ok = [r.get("ok", False) for r in results]
    return {
        "runs": runs, "passed": int(sum(ok)), "all_open": all(r["opens"] for r in results),
        "records_min": min(r.get("records", 0) for r in results),
        "records_max": max(r.get("records", 0) for r in results),
        "torn_tails": sum(1 for r in results if r.get("ignored_tail_bytes", 0) > 0),
        "records_beyond_last_flush_mean": float(np.mean([r.get("records", 0) - r["flushed"] for r in results])),
        "failures": [r for r in results if not r.get("ok", False)][:5],
    }


def flatsat_runs(runs: int, seed: int, folder: Path) -> dict:
    from ...loop.outputs import BLOCK_ROWS
    from ...recording.logfile import LogWriter
    from .. import config as hc
    from ..replay import load_log, replay

    flush_s = LogWriter.__init__.__defaults__[1]
    gyro = hc.load_flatsat().gyro                            # the built-in flatsat's runs below
    block_s = BLOCK_ROWS / gyro.odr_hz
    fifo_s = gyro.fifo_watermark / gyro.odr_hz               # a sample waits up to a watermark for its step
    rng = random.Random(seed + 77)
    results = []
    for k in range(runs):
        out = folder / f"flatsat{k}"
        cmd = [sys.executable, "-m", "gyrostar", "run", "--duration", "40", "--no-plots", "--out", str(out),
               "--seed", str(seed + k)]
        p = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        log = out / "flatsat.gslog"
        t_end = time.monotonic() + 120.0
        while not log.exists() and time.monotonic() < t_end and p.poll() is None:
            time.sleep(0.05)
        # the loop starts a few seconds after the log opens (numba load, acquisition)
        delay = rng.uniform(6.0, 20.0)
        time.sleep(delay)
        t_kill = time.monotonic()
        p.send_signal(signal.SIGKILL)
        p.wait()
        res = {"run": k, "killed_after_log_open_s": round(delay, 2)}
        try:
            lg = load_log(log)
            outs = lg["outputs"]
            res["opens"] = True
            res["outputs"] = int(len(outs))
            res["ignored_tail_bytes"] = lg["report"].ignored_tail_bytes
            res["last_output_age_s"] = float(t_kill - outs["t"][-1]) if len(outs) else None
            rp = replay(log)
            res["replayed"] = rp["replayed_outputs"]
            res["prefix_exact"] = rp["prefix_exact"]
            age = res["last_output_age_s"]
            res["ok"] = bool(rp["prefix_exact"] and rp["replayed_outputs"] >= len(outs) - 256
                             and age is not None and age < flush_s + block_s + fifo_s + 0.25)
        except Exception as exc:  # noqa: BLE001 - any failure to open or replay is the finding
            res["opens"] = res.get("opens", False)
            res["error"] = f"{type(exc).__name__}: {exc}"
            res["ok"] = False
        results.append(res)
    return {"runs": runs, "passed": sum(r["ok"] for r in results), "writer_flush_s": flush_s,
            "output_block_s": block_s, "fifo_watermark_s": fifo_s, "results": results}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m gyrostar.hil.reliability.recorder_kill",
                                 description=__doc__.split("\n")[0])
    ap.add_argument("--runs", type=int, default=100)
    ap.add_argument("--flatsat-runs", type=int, default=5)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--child", nargs=3, metavar=("LOG", "SIDE", "SEED"), help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.child:
        child(a.child[0], a.child[1], int(a.child[2]))
        return 0
    with tempfile.TemporaryDirectory(prefix="gyrostar-kill-") as tmp:
        s = {"synthetic": synthetic_runs(a.runs, a.seed, Path(tmp))}
        if a.flatsat_runs:
            s["flatsat"] = flatsat_runs(a.flatsat_runs, a.seed, Path(tmp))
    s["pass"] = s["synthetic"]["passed"] == a.runs and (not a.flatsat_runs or s["flatsat"]["passed"] == a.flatsat_runs)
    print(json.dumps(s, indent=1))
    return 0 if s["pass"] else 1


if __name__ == "__main__":
    sys.exit(main())
