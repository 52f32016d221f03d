"""``gyrostar fw TARGET``: camera-head firmware tools."""

from . import group

TARGETS = {
    "build": "gyrostar.fwtools.cli_build",
    "host": "gyrostar.fwtools.cli_host",
    "arm": "gyrostar.fwtools.cli_arm",
    "ping": "gyrostar.fwtools.cli_ping",
    "spots": "gyrostar.fwtools.cli_spots",
}


def configure(parser) -> None:
    group.add_targets(parser, TARGETS, dest="target")


run = group.run_target
