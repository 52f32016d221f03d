"""``gyrostar replay LOG``: feed a recorded log back through the driver, or export it."""

from __future__ import annotations

from . import group
from .main import add_json, add_view


def configure(parser) -> None:
    parser.add_argument("log", metavar="LOG", help="recorded log file")
    parser.add_argument("--export", choices=["csv", "hdf5", "aem", "calib"], default=None,
                        help="export instead of replaying (calib: the .npz that camera, alignment and "
                             "gyro-scale calibration read)")
    parser.add_argument("--out", metavar="PATH", default=None,
                        help="export path (with --export; an existing file is refused, a log always)")
    parser.add_argument("--force", action="store_true", help="overwrite an existing export file at --out")
    parser.add_argument("--check", action="store_true",
                        help="exit 1 when the replayed outputs differ from the recorded ones or the log is "
                             "corrupt (without it the verdict is printed and the exit is 0)")
    parser.add_argument("--compare-calibration", metavar="TOML", default=None,
                        help="simulated runs: compare a calibration file with the simulator's true devices")
    add_view(parser)
    add_json(parser)


def run(args) -> int:
    return group.run_registered("replay", args)   # gyrostar.hil.replay (ground code), by entry point
