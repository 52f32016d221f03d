"""Human output never says 'nan' for 'never'; summaries of runs that never tracked say so."""

from gyrostar.core.eval_centroid import _after
from gyrostar.hil.runner import human_summary


def test_never_is_printed_as_never():
    assert _after(float("nan")) == "never" and _after(None) == "never" and _after(2.5) == "after 2.5 s"


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
        if isinstance(action, (argparse._HelpAction, argparse._StoreTrueAction)):
            assert action.help, action.dest
            continue
        assert action.help, f"--{action.dest} has no help text"
        assert "default" in action.help, f"--{action.dest} does not say its default: {action.help!r}"
