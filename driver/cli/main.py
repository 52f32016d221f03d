"""``gyrostar`` console script: parses the command line and dispatches.

Sub-commands (each has ``--help``):

    run        the coupled 400/100 Hz loop (built-in simulated flatsat by default)
    eval       evaluations that reproduce the papers' figures (starcount, centroid, starid)
    bench      speed benchmarks, each a ratio against a baseline measured in the same run
    calibrate  field calibration (gyro-static, gyro-scale, dark, camera, alignment)
    replay     feed a recorded log back through the driver; export it
    fw         camera-head firmware tools (build, host program, ARM image, ping)
    sim        the physical simulator (frame rendering)

Exit codes: see :data:`gyrostar.errors.EXIT_CODES` (also printed by ``gyrostar --help``).
"""

from __future__ import annotations

import argparse
import importlib
import logging
import sys

from .. import __version__
from ..errors import EXIT_CODES, GyrostarError
from . import group

log = logging.getLogger("gyrostar")

# name -> (help, module). A module exposes configure(parser) and run(args) -> int.
COMMANDS: dict[str, tuple[str, str]] = {
    "run": ("run the coupled loop (default: built-in simulated flatsat, ~30 s)", "gyrostar.cli.run"),
    "eval": ("evaluations reproducing the papers' simulations", "gyrostar.cli.evaluate"),
    "bench": ("speed benchmarks with same-run baselines (ratios)", "gyrostar.cli.bench"),
    "calibrate": ("field calibration: gyro, dark frames, camera, alignment", "gyrostar.cli.calibrate"),
    "replay": ("replay a recorded log through the driver; export CSV/HDF5", "gyrostar.cli.replay"),
    "fw": ("camera-head firmware: build, host program, ARM image, ping", "gyrostar.cli.fw"),
    "sim": ("physical simulator: render frames", "gyrostar.cli.sim"),
}


def build_parser() -> argparse.ArgumentParser:
    codes = "\n".join(f"  {code:>3}  {text}" for code, text in EXIT_CODES.items())
    parser = argparse.ArgumentParser(
        prog="gyrostar",
        description="gyrostar — gyro-coupled star tracker software.",
        epilog=f"exit codes:\n{codes}",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--version", action="version", version=f"gyrostar {__version__}")
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument("-v", "--verbose", action="count", default=0, help="more log output (-vv debug)")
    common.add_argument("-q", "--quiet", action="store_const", const=-1, dest="verbose",
                        help="errors only, no progress bars")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name, (text, module_path) in COMMANDS.items():
        p = sub.add_parser(name, help=text, description=text, parents=[common],
                           epilog=f"exit codes:\n{codes}",
                           formatter_class=argparse.RawDescriptionHelpFormatter)
        module = importlib.import_module(module_path)
        module.configure(p)
        p.set_defaults(_run=module.run)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    from .. import logs

    logs.setup(args.verbose)
    try:
        return int(args._run(args) or 0)
    except GyrostarError as exc:
        log.error("%s", exc)
        return exc.exit_code
    except KeyboardInterrupt:
        log.error("interrupted")
        return 130


def add_json(parser: argparse.ArgumentParser) -> None:
    """The common --json flag for commands that report figures."""
    parser.add_argument("--json", action="store_true",
                        help="print one JSON object on stdout (human text goes to stderr)")


run_target = group.run_target

if __name__ == "__main__":
    sys.exit(main())
