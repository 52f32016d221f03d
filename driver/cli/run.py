"""``gyrostar run``: the coupled loop on the built-in simulated flatsat or a real one.

The loop itself lives in :mod:`gyrostar.hil.runner`; this module only parses arguments.
"""

from __future__ import annotations

from . import group
from .argtypes import non_blank, run_seconds, seed
from .main import add_json, add_view


def configure(parser) -> None:
    parser.add_argument("--config", metavar="TOML", help="flatsat config (default: built-in simulated flatsat)")
    parser.add_argument("--duration", type=run_seconds, default=None, metavar="S",
                        help="run length in seconds of flatsat time (default: the scenario's, ~30 s); every "
                             "output is kept in memory for the figures, about 1.9 GB an hour: a run longer than 80 %% "
                             "of the available memory allows is refused at the start")
    parser.add_argument("--scenario", type=non_blank, default=None,
                        help="built-in scenario name, TOML path, or mc:SEED@DURATION (a random Monte Carlo "
                             "scenario; default: demo, bench when the head is real)")
    parser.add_argument("--calibration", metavar="TOML", default=None,
                        help="calibration file from gyrostar calibrate (overrides the config's 'calibration' key)")
    parser.add_argument("--seed", type=seed, default=1, help="simulator seed (0 … 2³² − 1)")
    parser.add_argument("--out", metavar="DIR", default=None, help="run folder (default: runs/<timestamp>)")
    parser.add_argument("--no-plots", action="store_true", help="skip the PNG plots")
    parser.add_argument("--realtime", action="store_true",
                        help="ask for the config's SCHED_FIFO priority / CPU affinity (the loop always runs on "
                             "the monotonic clock: the emulated head's exposures take real time)")
    parser.add_argument("--fast", action="store_true",
                        help="run the emulated devices on a simulated clock in lock-step with the loop, as fast as "
                             "the host computes (same loop, log and figures; not with --realtime)")
    add_view(parser)
    add_json(parser)


def run(args) -> int:
    return group.run_registered("run", args)      # gyrostar.hil.runner (ground code), by entry point
