"""``gyrostar calibrate NAME``: field calibration from live devices, a log, or --simulate."""

from . import group

TARGETS = {
    "gyro-static": "gyrostar.calibration.gyro_static",
    "gyro-scale": "gyrostar.calibration.gyro_scale",
    "dark": "gyrostar.calibration.dark",
    "camera": "gyrostar.calibration.camera",
    "alignment": "gyrostar.calibration.alignment",
}


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
