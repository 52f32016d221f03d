"""``gyrostar sim TARGET``: the physical simulator."""

from . import group

TARGETS = group.registered_targets("sim")   # the simulator (gyrostar.mocks), by entry point


def configure(parser) -> None:
    group.add_targets(parser, TARGETS, dest="target")


run = group.run_target
