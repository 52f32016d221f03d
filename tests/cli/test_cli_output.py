"""Human output never says 'nan' for 'never'; summaries of runs that never tracked say so."""

from gyrostar.hil.evaluation.eval_centroid import after_text
from gyrostar.hil.runner import human_summary


def test_never_is_printed_as_never():
    assert after_text(float("nan")) == "never" and after_text(None) == "never" and after_text(2.5) == "after 2.5 s"


def test_run_summary_of_a_run_that_never_tracked():
    r = {"scenario": "demo", "flatsat": "sim", "duration_s": 3.0, "wall_s": 3.1, "realtime": False,
         "attitude_error_arcsec_1sigma": None, "track_fraction": 0.0, "mode_seconds": {"ACQUIRE": 3.0},
         "frames": 5, "gyro_samples": 1200, "samples_lost": 0, "latency_p99_ms": None, "latency_clock": "host",
         "cpu_percent": None, "overruns": 0, "numba_startup": {"seconds": 0.5, "cache_hits": 14, "compiled": 0},
         "run_folder": "runs/x", "interrupted": True, "ran_s": 1.25,
         "acceptance": {"applied": False, "note": "run interrupted", "checks": {}}}
    text = human_summary(r)
    assert "never in TRACK" in text and "nan" not in text.lower().replace("n/a", "")
    assert "1.2 s (interrupted) of 3.0 s" in text and "acceptance not applied: run interrupted" in text


def _subparser(parser, *names):
    import argparse

    for name in names:
        sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
        parser = sub.choices[name]
    return parser


def test_every_eval_starid_option_has_help_and_default():
    import argparse

    from gyrostar.cli.main import build_parser

    p = _subparser(build_parser(), "eval", "starid")
    for action in p._actions:
        if isinstance(action, (argparse._HelpAction, argparse._StoreTrueAction)) or action.dest == "verbose":
            assert action.help, action.dest      # -v/-q: the common flags of every command
            continue
        assert action.help, f"--{action.dest} has no help text"
        assert "default" in action.help, f"--{action.dest} does not say its default: {action.help!r}"


def test_run_summary_says_what_the_head_stream_and_acquisition_did():
    r = {"scenario": "demo", "flatsat": "sim", "duration_s": 3.0, "wall_s": 3.1, "realtime": False,
         "attitude_error_arcsec_1sigma": 3.9, "floor_arcsec": 4.1, "mode_seconds": {"TRACK": 3.0},
         "frames": 300, "gyro_samples": 1200, "samples_lost": 0, "latency_p99_ms": 0.1, "latency_clock": "host",
         "cpu_percent": 15.0, "overruns": 0, "numba_startup": {"seconds": 0.5, "cache_hits": 14, "compiled": 0},
         "run_folder": "runs/x", "head_mode": "stream", "frame_rate_hz": 97.0, "link_utilisation": 0.697,
         "exposure_to_output_ms_p50": 16.2, "acquisition_image": "spots",
         "link_budget": {"preset": "uart-921k", "frames_stars_cut": 2492, "rate_changes": []}}
    text = human_summary(r)
    assert "97.0 frames/s, link uart-921k 70 % used, exposure → output p50 16.2 ms" in text
    assert "stars cut for the link in 2492 frames" in text and "the head's spot list (FIND_SPOTS)" in text
    r["acquisition_image"] = "full_frame"
    assert "lost-in-space image: full frames" in human_summary(r)


def test_tables_keep_their_width_off_a_terminal(capsys):
    """A rich table printed to a pipe is not squeezed into 80 columns (bench tables were)."""
    from gyrostar.cli.output import table_console
    from rich.table import Table

    table = Table(title="wide")
    for col in ("suite", "case", "µs", "baseline µs", "ratio", "note"):
        table.add_column(col)
    table.add_row("loop_step", "predict_batch_with_twelve_tracked_stars", "12.3", "45.6", "3.7",
                  "numba vs numpy, one FIFO batch of ten samples")
    table_console(False).print(table)
    out = capsys.readouterr().out
    row = next(ln for ln in out.splitlines() if "predict_batch" in ln)
    assert "predict_batch_with_twelve_tracked_stars" in row and "one FIFO batch of ten samples" in row
    assert len(row) > 80
