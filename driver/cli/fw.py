"""``gyrostar fw TARGET``: camera-head firmware tools."""

from . import group

TARGETS = {
    "build": "gyrostar.head.fw_build",
    "ping": "gyrostar.head.fw_ping",
}


def configure(parser) -> None:
    group.add_targets(parser, TARGETS, dest="target")


run = group.run_target
