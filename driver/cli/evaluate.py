"""``gyrostar eval TARGET``: evaluations that reproduce the papers' simulations."""

from . import group

# target -> module exposing HELP, configure(parser), run(args)
TARGETS = group.registered_targets("eval")   # ground code (simulator, evaluations) by entry point


def configure(parser) -> None:
    group.add_targets(parser, TARGETS, dest="target")


run = group.run_target
