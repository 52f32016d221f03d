"""``gyrostar sim TARGET``: the physical simulator."""

from . import group

TARGETS = {
    "frame": "gyrostar.mocks.frame_cli",
}


def configure(parser) -> None:
    group.add_targets(parser, TARGETS, dest="target")


run = group.run_target
