"""``gyrostar calibrate NAME``: field calibration from live devices, a log, or --simulate."""

from . import group

TARGETS = group.registered_targets("calibrate")   # ground front ends (gyrostar.hil.calibrate), by entry point


def configure(parser) -> None:
    group.add_targets(parser, TARGETS, dest="target")


def run(args) -> int:
    """Run the target; a failure leaves no empty report folder behind."""
    try:
        return group.run_target(args)
    except BaseException:
        from ..calibration.report import remove_empty_reports

        remove_empty_reports()
        raise
