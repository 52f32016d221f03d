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


run = group.run_target
