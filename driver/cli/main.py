"""``gyrostar`` console script: parses the command line and dispatches.

Sub-commands (each has ``--help``):

    run        the coupled 400/100 Hz loop (built-in simulated flatsat by default)
    eval       evaluations that reproduce the papers' figures (starcount, centroid, starid)
    bench      speed benchmarks, each a ratio against a baseline measured in the same run
    calibrate  field calibration (gyro-static, gyro-scale, dark, camera, alignment)
    replay     feed a recorded log back through the driver; export it
    fw         camera-head firmware tools (build, host program, ARM image, ping, spots)
    sim        the physical simulator (frame rendering)
    solve      plate-solve night-sky image files (attitude, field of view, lens; WCS, CSV, PNG)

Exit codes: see :data:`gyrostar.errors.EXIT_CODES` (also printed by ``gyrostar --help``).
Every failure is one line on stderr (``gyrostar COMMAND: error: ...``) and, with
``--json``, one object ``{"error": ..., "exit_code": N}`` on stdout; no traceback.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import sys

from .. import __version__
from ..errors import EXIT_CODES, GyrostarError
from . import group, interrupt
from .output import emit_error

log = logging.getLogger("gyrostar")

# name -> (help, module). A module exposes configure(parser) and run(args) -> int.
COMMANDS: dict[str, tuple[str, str]] = {
    "run": ("run the coupled loop (default: built-in simulated flatsat, ~30 s)", "gyrostar.cli.run"),
    "eval": ("evaluations reproducing the papers' simulations", "gyrostar.cli.evaluate"),
    "bench": ("speed benchmarks with same-run baselines (ratios)", "gyrostar.cli.bench"),
    "calibrate": ("field calibration: gyro, dark frames, camera, alignment", "gyrostar.cli.calibrate"),
    "replay": ("replay a recorded log through the driver; export CSV, HDF5, AEM or calibration inputs",
               "gyrostar.cli.replay"),
    "fw": ("camera-head firmware: build, host program, ARM image, ping, spots", "gyrostar.cli.fw"),
    "sim": ("physical simulator: render frames", "gyrostar.cli.sim"),
    "solve": ("plate-solve night-sky images (no field-of-view hint): attitude, field of view, lens; WCS, CSV, PNG",
              "gyrostar.cli.solve"),
}

# OS errors on paths the user named are usage errors; any other OS error is a device/link one
_PATH_ERRORS = (FileNotFoundError, FileExistsError, IsADirectoryError, NotADirectoryError, PermissionError)


class Parser(argparse.ArgumentParser):
    """argparse with one-line errors (exit 2) and a JSON error object when --json was given."""

    def error(self, message: str):
        text = f"{self.prog}: error: {message} (see {self.prog} --help)"
        sys.stderr.write(text + "\n")
        emit_error(_argv_has_json(), text, 2)
        sys.exit(2)


def _argv_has_json(argv: list[str] | None = None) -> bool:
    return "--json" in (sys.argv[1:] if argv is None else argv)


def build_parser() -> argparse.ArgumentParser:
    codes = "\n".join(f"  {code:>3}  {text}" for code, text in EXIT_CODES.items())
    parser = Parser(
        prog="gyrostar",
        description="gyrostar — gyro-coupled star tracker software.",
        epilog=f"exit codes:\n{codes}",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--version", action="version", version=f"gyrostar {__version__}")
    group.add_verbosity(parser)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True, parser_class=Parser)
    for name, (text, module_path) in COMMANDS.items():
        p = sub.add_parser(name, help=text, description=text, epilog=f"exit codes:\n{codes}",
                           formatter_class=argparse.RawDescriptionHelpFormatter)
        group.add_verbosity(p)
        module = importlib.import_module(module_path)
        module.configure(p)
        p.set_defaults(_run=module.run, _parser=p)     # a target's own parser overrides _parser
    return parser


def main(argv: list[str] | None = None) -> int:
    with interrupt.watch():
        try:
            parser = build_parser()
            args, extra = parser.parse_known_args(argv)
            if extra:       # named by the deepest (sub-)command that took the rest: its own --help
                getattr(args, "_parser", parser).error(f"unrecognized arguments: {' '.join(extra)}")
        except KeyboardInterrupt:
            sys.stderr.write(f"gyrostar: ERROR: {interrupt.reason()}\n")
            emit_error(_argv_has_json(argv), interrupt.reason(), 130)
            return 130
        from .. import logs

        verbosity = getattr(args, "verbose", 0)
        logs.setup(verbosity)
        as_json = bool(getattr(args, "json", False))
        try:
            return int(args._run(args) or 0)
        except GyrostarError as exc:
            return _fail(as_json, str(exc), exc.exit_code)
        except KeyboardInterrupt:
            return _fail(as_json, interrupt.reason(), 130)
        except Exception as exc:  # noqa: BLE001 - every failure is one line, never a traceback
            if interrupt.seen():     # a Ctrl-C surfacing from native code (SystemError, EOFError...)
                return _fail(as_json, interrupt.reason(), 130)
            if isinstance(exc, _PATH_ERRORS):
                return _fail(as_json, _os_text(exc), 2)
            if isinstance(exc, OSError):
                return _fail(as_json, _os_text(exc), 3)
            log.debug("unexpected error", exc_info=True)
            hint = "" if verbosity >= 2 else " (run with -vv for the traceback)"
            return _fail(as_json, f"internal error: {type(exc).__name__}: {exc}{hint}", 1)


def _os_text(exc: OSError) -> str:
    if exc.strerror and exc.filename:
        return f"{exc.filename}: {exc.strerror}"
    return exc.strerror or str(exc)


def _fail(as_json: bool, message: str, code: int) -> int:
    log.error("%s", message)
    emit_error(as_json, message, code)
    return code


def add_json(parser: argparse.ArgumentParser) -> None:
    """The common --json flag for commands that report figures."""
    parser.add_argument("--json", action="store_true",
                        help="print one JSON object on stdout (human text goes to stderr)")


def add_view(parser: argparse.ArgumentParser) -> None:
    """The live view's flags of ``run`` and ``replay`` (rerun; the optional extra ``view``)."""
    from .argtypes import int_in

    parser.add_argument("--view", action="store_true",
                        help="show the run live in rerun's native viewer (needs a display and the 'view' extra)")
    parser.add_argument("--view-save", metavar="FILE.rrd", default=None,
                        help="write the live view to a rerun recording (an existing file is refused)")
    parser.add_argument("--view-serve", metavar="PORT", nargs="?", type=int_in(1024, 65535), const=9090,
                        default=None, help="serve rerun's web viewer on 127.0.0.1:PORT (default 9090); "
                                           "after the run it serves until Ctrl-C")


run_target = group.run_target

if __name__ == "__main__":
    sys.exit(main())
