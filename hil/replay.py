"""``gyrostar replay LOG``: feed a flatsat log back through the same driver and loop.

Replay rebuilds the gyro driver, the head client and the loop exactly as the run did
(from the log's META record), but on the replay taps of :mod:`gyrostar.recording.taps`:
every bus transaction, link frame and clock reading is answered from the log, and every
request the driver makes is checked against what it made when recording. The replayed
outputs are compared with the recorded OUTPUT records byte for byte (``--check`` makes a
mismatch an error, exit code 1).

``--export aem --out X.aem`` writes a CCSDS Attitude Ephemeris Message (:mod:`gyrostar.telemetry.aem`).

``--export calib --out X.npz`` replays the log and writes what camera, alignment and
gyro-scale calibration read (:mod:`gyrostar.hil.calib_export`).

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
from ..files import whole_or_nothing
from ..loop.record import OUTPUT_DTYPE, TRUTH_DTYPE
from ..recording import logfile as lf


def load_log(path: str | Path, on_progress=None, keep_records: bool = True) -> dict:
    """Split a log into its META, records by kind, outputs and truth. ``report`` tells what
    the reader skipped (corrupt stretches) or ignored (a cut-off tail); ``complete`` is
    False for a log without the run's closing summary (cut short by a crash or a kill).
    ``keep_records`` False keeps only the META, OUTPUT, TRUTH and EVENT records (``records``
    is then those): an export of a long log holds its outputs, not every bus transaction
    and link frame."""
    report = lf.ReadReport()
    wanted = None if keep_records else (lf.META, lf.OUTPUT, lf.TRUTH, lf.EVENT)
    recs = [r for r in lf.read_records(path, report, on_progress) if wanted is None or r.kind in wanted]
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


def log_state(log: dict) -> dict:
    """What an export of ``log`` (from :func:`load_log`) holds of the recording: the corrupt
    bytes skipped, the cut-off tail ignored, and whether the run's closing summary is there."""
    report = log["report"]
    return {"log_skipped_bytes": report.skipped_bytes, "log_skipped_places": len(report.skipped),
            "log_tail_ignored_bytes": report.ignored_tail_bytes, "log_complete": bool(log["complete"])}


def log_state_text(res: dict) -> str:
    """The export line's note on a damaged or cut-short log ("" for a whole one)."""
    notes = []
    if res.get("log_skipped_bytes"):
        notes.append(f"CORRUPT LOG: {res['log_skipped_bytes']} bytes skipped in {res['log_skipped_places']} "
                     "place(s), the export holds the intact records only")
    if res.get("log_tail_ignored_bytes"):
        notes.append(f"the log ends in {res['log_tail_ignored_bytes']} bytes of a torn record (ignored)")
    if res.get("log_complete") is False:
        notes.append("the log has no closing summary: the run was cut short, the export holds what was recorded")
    return "".join("; " + n for n in notes)


def replayed_records(records, replayed: np.ndarray):
    """The log's records with each OUTPUT record's rows replaced by the replay's rows in its
    place (the run's time line, what the replayed driver computed); OUTPUT records past the
    replay's end are left out."""
    pos = 0
    for r in records:
        if r.kind != lf.OUTPUT:
            yield r
            continue
        n = len(r.payload) // OUTPUT_DTYPE.itemsize
        if pos >= len(replayed):
            continue
        yield lf.Record(r.kind, r.channel, r.t_ns, replayed[pos:pos + n].tobytes())
        pos += n


def replay(path: str | Path, progress=None, view=None) -> dict:
    """Replay a log through the driver and loop; compare outputs. Returns the figures.

    ``verdict``: ``bit-exact`` (every recorded output replayed identically), ``prefix``
    (a log cut short: the outputs it holds replay identically, the run's end is missing),
    ``corrupt`` (the reader skipped corrupt bytes: the replay is not a check of the whole
    run) or ``different`` (``first_difference_at`` names the first differing output)."""
    from . import flatsat
    from .run_memory import check_log_fits

    check_log_fits(path, replay=True)         # one line, not the kernel's OOM killer
    if progress is None:
        progress = _no_progress
    with progress("reading log", None) as advance_read:
        log = load_log(path, lambda pos, size: advance_read(pos, size))
    recorded = log["outputs"]
    report = log["report"]
    if view is not None:
        view.start()
    if not len(recorded):
        why = next((e["aborted"] for e in log["events"] if "aborted" in e), None)
        raise ConfigError(f"log {path} holds no loop outputs: nothing to replay (the run "
                          + (f"stopped during start-up: {why})" if why else "ended before its first output)"))
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
    shown = None
    if view is not None:     # the recorded run on its own time line, with the replay's outputs
        with progress("view", None) as _:
            view.send_records(replayed_records(log["records"], replayed))
            shown = view.close()
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
    } | ({"view": shown} if shown is not None else {})


@contextmanager
def _no_progress(description, total):
    yield lambda *a: None


def _check_target(log: Path, out: Path, force: bool) -> None:
    """Refuse an export path that would destroy data: the log itself, any other gyrostar log,
    or (without ``force``) any existing file."""
    if out.is_dir():
        raise ConfigError(f"--out {out} is a folder: give the export file's path")
    if not out.parent.is_dir():
        raise ConfigError(f"--out {out}: folder {out.parent} does not exist")
    if not out.exists():
        return
    if log.exists() and out.samefile(log):
        raise ConfigError(f"--out {out} is the log being exported: give another path")
    try:
        with open(out, "rb") as fh:
            is_log = fh.read(len(lf.MAGIC)) == lf.MAGIC
    except OSError:
        is_log = False
    if is_log:
        raise ConfigError(f"--out {out} is a gyrostar log: an export never overwrites one")
    if not force:
        raise ConfigError(f"--out {out} exists (--force overwrites it)")


def export(path: str | Path, fmt: str, out: str | Path, force: bool = False) -> dict:
    """Write the log's outputs as ``fmt`` (csv, hdf5, aem, calib) to ``out``; an existing
    ``out`` is refused unless ``force`` (a log never is overwritten)."""
    out = Path(out)
    _check_target(Path(path), out, force)
    if fmt not in ("csv", "hdf5", "aem", "calib"):
        raise ConfigError(f"unknown export format {fmt!r} (csv, hdf5, aem, calib)")
    from .run_memory import check_log_fits

    check_log_fits(path, replay=fmt == "calib")      # calib replays the log; the others read its outputs
    if fmt == "calib":
        from .calib_export import export_calib

        return export_calib(path, out)
    log = load_log(path, keep_records=False)
    recs = log["outputs"]
    res = {"log": str(path), "export": fmt, "out": str(out), "outputs": int(len(recs)),
           "truth": log["truth"] is not None} | log_state(log)
    try:
        with whole_or_nothing(out) as part:
            if fmt == "aem":
                from ..telemetry import aem, timescale

                counts = aem.write(part, recs, timescale.from_meta(log["meta"].get("time")))
                res |= counts | {"outputs": counts["lines"]}
            elif fmt == "csv":
                _export_csv(recs, log["truth"], log["meta"], out, part)
            else:
                _export_hdf5(recs, log["truth"], log["meta"], part)
    except OSError as exc:
        raise ConfigError(f"--out {out}: cannot write the export: {exc.strerror or exc}") from exc
    return res


def _export_csv(recs: np.ndarray, truth, meta: dict, out: Path, part: Path | None = None) -> None:
    """CSV of the schema's columns (+ UTC, star ids, truth) written to ``part`` (default
    ``out``), and a W3C CSVW metadata file ``<out>-metadata.json`` giving every column's unit
    and meaning (written whole, before the CSV is renamed into place)."""
    from ..telemetry import schema, timescale

    tmap = timescale.from_meta(meta.get("time"))
    cols = schema.table(recs, tmap)
    utc = tmap.utc_iso(recs["t"]) if tmap is not None and len(recs) else [""] * len(recs)
    has_truth = truth is not None and len(truth) == len(recs)
    names = list(cols) + ["utc", "star_ids"] + (["true_q_x", "true_q_y", "true_q_z", "true_q_w"] if has_truth else [])
    with open(part or out, "w") as fh:
        fh.write(",".join(names) + "\n")
        for i, r in enumerate(recs):
            row = [repr(v.item()) if v.dtype.kind == "f" else str(v.item()) for v in (c[i] for c in cols.values())]
            row += [utc[i], " ".join(str(v) for v in r["star_id"][r["star_id"] >= 0])]
            if has_truth:
                row += [repr(float(v)) for v in truth[i]["q"]]
            fh.write(",".join(row) + "\n")
    desc = [{"name": c.name, "titles": c.name, "datatype": "double" if c.dtype.startswith("f") else "integer",
             "unit": c.unit, "dc:description": c.description} for c in schema.COLUMNS]
    desc += [{"name": "utc", "datatype": "dateTime", "unit": "",
              "dc:description": "UTC of the same instant (ISO 8601)"},
             {"name": "star_ids", "datatype": "string", "unit": "", "dc:description": "catalog ids of tracked stars"}]
    if has_truth:
        desc += [{"name": f"true_q_{a}", "datatype": "double", "unit": "1",
                  "dc:description": f"simulator truth attitude ICRS → body, {a} component"} for a in "xyzw"]
    with whole_or_nothing(Path(f"{out}-metadata.json")) as meta_part:
        meta_part.write_text(json.dumps(
            {"@context": "http://www.w3.org/ns/csvw", "url": Path(out).name, "tableSchema": {"columns": desc},
             "dc:description": "gyrostar loop outputs at the gyro rate; time mapping in 'time'",
             "time": meta.get("time")}, indent=1))


def _export_hdf5(recs: np.ndarray, truth, meta: dict, out: Path) -> None:
    """HDF5: the raw records (``outputs``), one dataset per schema column under ``columns``
    with ``unit`` and ``description`` attributes, UTC strings, truth, the run's META."""
    import h5py

    from ..telemetry import schema, timescale

    tmap = timescale.from_meta(meta.get("time"))
    with h5py.File(out, "w") as h5:
        h5.create_dataset("outputs", data=recs)
        grp = h5.create_group("columns")
        cols = schema.table(recs, tmap)
        for c in schema.COLUMNS:
            ds = grp.create_dataset(c.name, data=cols[c.name])
            ds.attrs["unit"] = c.unit
            ds.attrs["description"] = c.description
        if tmap is not None and len(recs):
            ds = grp.create_dataset("utc", data=np.array(tmap.utc_iso(recs["t"]), dtype=h5py.string_dtype()))
            ds.attrs["unit"] = ""
            ds.attrs["description"] = "UTC of the same instant (ISO 8601)"
        if truth is not None:
            h5.create_dataset("truth", data=truth)
        h5.attrs["meta"] = json.dumps(meta)


def verdict_text(res: dict) -> str:
    """The one-line verdict of a replay."""
    v = res["verdict"]
    stop = res.get("stopped") or ""
    why = f"; the replay stopped at step {res['steps']}: {stop}" if stop.startswith("diverged") else ""
    if v == "bit-exact":
        return "bit-exact"
    if v == "prefix":
        return (f"PREFIX: the log was cut short (no end-of-run record; {res['log_tail_ignored_bytes']} bytes of "
                f"torn tail); its {res['compared_outputs']} outputs replay bit-exact")
    if v == "corrupt":
        sk = res["log_skipped"][0]
        return (f"CORRUPT LOG: {res['log_skipped_bytes']} bytes skipped in {len(res['log_skipped'])} place(s), "
                f"first at byte {sk['offset']} ({sk['reason']}); the records around them replayed "
                + ("bit-exact" if res["prefix_exact"] else f"DIFFERENT from output {res['first_difference_at']}")
                + why)
    return f"DIFFERENT (first difference at output {res['first_difference_at']}){why}"


def run(args) -> int:
    from .view.feed import ViewFeed, check, options_from

    view_opts = options_from(args)
    if view_opts is not None and (args.export or getattr(args, "compare_calibration", None)):
        raise ConfigError("--view, --view-save and --view-serve show a replay: not with --export or "
                          "--compare-calibration")
    if getattr(args, "compare_calibration", None):
        from .calib_truth import compare, text

        res = compare(args.log, args.compare_calibration)
        emit(args, res, text(res))
        return 0
    from ..cli.output import progress

    if args.out and not args.export:
        raise ConfigError("--out is the export's path: give --export csv|hdf5|aem|calib with it")
    if getattr(args, "force", False) and not args.export:
        raise ConfigError("--force overwrites an export: give --export with it")
    if args.export:
        if not args.out:
            raise ConfigError("--export needs --out PATH")
        if args.check:
            raise ConfigError("--check compares a replay with the log; an export does not replay: "
                              "run them separately")
        res = export(args.log, args.export, args.out, force=getattr(args, "force", False))
        what = (f"{res['fields']} star fields ({res['star_observations']} stars; "
                f"{res['blended_observations_left_out']} of blended stars left out) and {res['gyro_samples']} gyro "
                "samples" if args.export == "calib" else f"{res['outputs']} outputs")
        emit(args, res, f"exported {what} to {res['out']} ({res['export']}){log_state_text(res)}")
        return 0
    view = None
    if view_opts is not None:
        check(view_opts)
        view = ViewFeed(view_opts, lossless=True)
    try:
        res = replay(args.log, lambda d, total: _bytes_or_items(args, d, total, progress), view=view)
    except BaseException:
        if view is not None:
            view.abort()
        raise
    human = (f"replayed {res['replayed_outputs']} outputs of {res['recorded_outputs']} recorded "
             f"in {res['steps']} loop steps: {verdict_text(res)}")
    if res.get("view"):
        v = res["view"]
        human += f"\n  view: {v['frames']} frames drawn ({v['shown']})" + (f"; {v['error']}" if v.get("error") else "")
    emit(args, res, human)
    if view is not None:
        view.serve_until_interrupted()
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
