"""``gyrostar replay LOG``: feed a flatsat log back through the same driver and loop.

Replay rebuilds the gyro driver, the head client and the loop exactly as the run did
(from the log's META record), but on the replay taps of :mod:`gyrostar.recording.taps`:
every bus transaction, link frame and clock reading is answered from the log, and every
request the driver makes is checked against what it made when recording. The replayed
outputs are compared with the recorded OUTPUT records byte for byte (``--check`` makes a
mismatch an error, exit code 1).

``--export csv|hdf5 --out PATH`` writes the recorded outputs (and truth, when the log has
it) instead: CSV with one row per output (quaternion, rates, bias, covariance diagonal,
the mid-exposure products: t_mid, q_mid and its variances, filtered and smoothed (_s),
mode, flags, stars), HDF5 (h5py) with the full structured arrays and the run's META.
"""

from __future__ import annotations

import json
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from ..cli.output import emit
from ..errors import ConfigError
from ..loop.record import OUTPUT_DTYPE, TRUTH_DTYPE
from ..recording import logfile as lf


def load_log(path: str | Path, on_progress=None) -> dict:
    """Split a log into its META, records by kind, outputs and truth. ``report`` tells what
    the reader skipped (corrupt stretches) or ignored (a cut-off tail); ``complete`` is
    False for a log without the run's closing summary (cut short by a crash or a kill)."""
    report = lf.ReadReport()
    recs = list(lf.read_records(path, report, on_progress))
    metas = [json.loads(r.payload) for r in recs if r.kind == lf.META]
    if not metas:
        raise ConfigError(f"log {path} has no META record: not a flatsat log "
                          f"({report.records} records{'; ' + report.describe() if report.describe() else ''})")
    outs = [r.payload for r in recs if r.kind == lf.OUTPUT]
    out = np.frombuffer(b"".join(outs), OUTPUT_DTYPE) if outs else np.zeros(0, OUTPUT_DTYPE)
    tr = [r.payload for r in recs if r.kind == lf.TRUTH]
    truth = np.frombuffer(b"".join(tr), TRUTH_DTYPE) if tr else None
    events = [json.loads(r.payload) for r in recs if r.kind == lf.EVENT]
    t0 = next((e["scenario_t0"] for e in events if "scenario_t0" in e), float(out["t"][0]) if len(out) else 0.0)
    complete = any("summary" in e for e in events) and report.ignored_tail_bytes == 0
    return {"meta": metas[0], "records": recs, "outputs": out, "truth": truth, "events": events,
            "report": report, "t0": t0, "complete": complete}


def replay(path: str | Path, progress=None) -> dict:
    """Replay a log through the driver and loop; compare outputs. Returns the figures.

    ``verdict``: ``bit-exact`` (every recorded output replayed identically), ``prefix``
    (a log cut short: the outputs it holds replay identically, the run's end is missing),
    ``corrupt`` (the reader skipped corrupt bytes: the replay is not a check of the whole
    run) or ``different`` (``first_difference_at`` names the first differing output)."""
    from . import flatsat

    if progress is None:
        progress = _no_progress
    with progress("reading log", None) as advance_read:
        log = load_log(path, lambda pos, size: advance_read(pos, size))
    recorded = log["outputs"]
    report = log["report"]
    got: list[np.ndarray] = []
    from ..loop.sinks import CallbackSink

    with progress("replaying", len(recorded) or None) as advance:
        def keep(r):
            got.append(r.copy())
            advance(len(r))

        loop, steps = flatsat.replay_loop(log["meta"], log["records"], [CallbackSink(keep)])
        n_steps, stop_reason = steps()
    replayed = np.concatenate(got) if got else np.zeros(0, OUTPUT_DTYPE)
    n = min(len(replayed), len(recorded))
    same_prefix = replayed[:n].tobytes() == recorded[:n].tobytes()
    first_diff = None
    if not same_prefix:
        a = replayed[:n].view(np.uint8).reshape(n, -1)
        b = recorded[:n].view(np.uint8).reshape(n, -1)
        first_diff = int(np.flatnonzero(np.any(a != b, axis=1))[0])
    bit_exact = bool(same_prefix and len(replayed) == len(recorded) and log["complete"])
    if report.skipped:
        verdict = "corrupt"
    elif not same_prefix:
        verdict = "different"
    elif bit_exact:
        verdict = "bit-exact"
    elif not log["complete"] and n > 0:
        verdict = "prefix"
    else:
        verdict = "different"
        first_diff = n
    return {
        "log": str(path),
        "scenario": log["meta"].get("scenario", {}).get("name"),
        "recorded_outputs": int(len(recorded)),
        "replayed_outputs": int(len(replayed)),
        "verdict": verdict,
        "bit_exact": bit_exact and not report.skipped,
        "prefix_exact": bool(same_prefix and n > 0),
        "compared_outputs": int(n),
        "first_difference_at": first_diff,
        "steps": n_steps,
        "stopped": stop_reason,
        "log_complete": log["complete"],
        "log_skipped_bytes": report.skipped_bytes,
        "log_skipped": [{"offset": off, "bytes": nb, "reason": why} for off, nb, why in report.skipped],
        "log_tail_ignored_bytes": report.ignored_tail_bytes,
        "log_tail_reason": report.tail_reason,
    }


@contextmanager
def _no_progress(description, total):
    yield lambda *a: None


def export(path: str | Path, fmt: str, out: str | Path) -> dict:
    out = Path(out)
    if out.is_dir():
        raise ConfigError(f"--out {out} is a folder: give the export file's path")
    if not out.parent.is_dir():
        raise ConfigError(f"--out {out}: folder {out.parent} does not exist")
    if fmt not in ("csv", "hdf5"):
        raise ConfigError(f"unknown export format {fmt!r} (csv, hdf5)")
    log = load_log(path)
    recs = log["outputs"]
    try:
        if fmt == "csv":
            _export_csv(recs, log["truth"], out)
        else:
            _export_hdf5(recs, log["truth"], log["meta"], out)
    except OSError as exc:
        raise ConfigError(f"--out {out}: cannot write the export: {exc.strerror or exc}") from exc
    return {"log": str(path), "export": fmt, "out": str(out), "outputs": int(len(recs)),
            "truth": log["truth"] is not None}


def _export_csv(recs: np.ndarray, truth, out: Path) -> None:
    cols = ["t", "seq", "mode", "flags", "n_stars", "qx", "qy", "qz", "qw", "wx", "wy", "wz", "bx", "by", "bz",
            "var_tx", "var_ty", "var_tz", "var_bx", "var_by", "var_bz", "latency_us", "star_ids",
            "t_mid", "qx_mid", "qy_mid", "qz_mid", "qw_mid", "var_tx_mid", "var_ty_mid", "var_tz_mid",
            "t_mid_s", "qx_mid_s", "qy_mid_s", "qz_mid_s", "qw_mid_s", "var_tx_mid_s", "var_ty_mid_s", "var_tz_mid_s"]
    has_truth = truth is not None and len(truth) == len(recs)
    if has_truth:
        cols += ["true_qx", "true_qy", "true_qz", "true_qw"]
    with open(out, "w") as fh:
        fh.write(",".join(cols) + "\n")
        for i, r in enumerate(recs):
            ids = " ".join(str(v) for v in r["star_id"][: r["n_stars"]])
            row = [repr(float(r["t"])), str(int(r["seq"])), str(int(r["mode"])), str(int(r["flags"])),
                   str(int(r["n_stars"]))]
            row += [repr(float(v)) for v in r["q"]] + [repr(float(v)) for v in r["omega"]]
            row += [repr(float(v)) for v in r["bias"]] + [repr(float(v)) for v in np.diag(r["cov"])]
            row += [repr(float(r["latency_us"])), ids, repr(float(r["t_mid"]))]
            row += [repr(float(v)) for v in r["q_mid"]] + [repr(float(v)) for v in np.diag(r["cov_mid"])]
            row += [repr(float(r["t_mid_s"]))] + [repr(float(v)) for v in r["q_mid_s"]]
            row += [repr(float(v)) for v in np.diag(r["cov_mid_s"])]
            if has_truth:
                row += [repr(float(v)) for v in truth[i]["q"]]
            fh.write(",".join(row) + "\n")


def _export_hdf5(recs: np.ndarray, truth, meta: dict, out: Path) -> None:
    import h5py

    with h5py.File(out, "w") as h5:
        h5.create_dataset("outputs", data=recs)
        if truth is not None:
            h5.create_dataset("truth", data=truth)
        h5.attrs["meta"] = json.dumps(meta)


def verdict_text(res: dict) -> str:
    """The one-line verdict of a replay."""
    v = res["verdict"]
    if v == "bit-exact":
        return "bit-exact"
    if v == "prefix":
        return (f"PREFIX: the log was cut short (no end-of-run record; {res['log_tail_ignored_bytes']} bytes of "
                f"torn tail); its {res['compared_outputs']} outputs replay bit-exact")
    if v == "corrupt":
        sk = res["log_skipped"][0]
        return (f"CORRUPT LOG: {res['log_skipped_bytes']} bytes skipped in {len(res['log_skipped'])} place(s), "
                f"first at byte {sk['offset']} ({sk['reason']}); the records around them replayed "
                + ("bit-exact" if res["prefix_exact"] else f"DIFFERENT from output {res['first_difference_at']}"))
    return f"DIFFERENT (first difference at output {res['first_difference_at']})"


def run(args) -> int:
    from ..cli.output import progress

    if args.export:
        if not args.out:
            raise ConfigError("--export needs --out PATH")
        res = export(args.log, args.export, args.out)
        emit(args, res, f"exported {res['outputs']} outputs to {res['out']} ({res['export']})")
        return 0
    res = replay(args.log, lambda d, total: _bytes_or_items(args, d, total, progress))
    human = (f"replayed {res['replayed_outputs']} outputs of {res['recorded_outputs']} recorded "
             f"in {res['steps']} loop steps: {verdict_text(res)}")
    emit(args, res, human)
    if args.check and res["verdict"] in ("corrupt", "different"):
        return 1
    return 0


@contextmanager
def _bytes_or_items(args, description, total, progress):
    """A progress bar: over bytes (``advance(pos, size)``) or items (``advance(n)``)."""
    with progress(args, description, total) as advance:
        state = {"pos": 0}

        def step(n, size=None):
            if size is None:
                advance(n)
            else:
                advance(n - state["pos"], total=size)
                state["pos"] = n

        yield step
