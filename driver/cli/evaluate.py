"""``gyrostar eval TARGET``: evaluations that reproduce the papers' simulations."""

from . import group

# target -> module exposing HELP, configure(parser), run(args)
TARGETS = {
    "starcount": "gyrostar.mocks.starcount",
    "centroid": "gyrostar.core.eval_centroid",
    "starid": "gyrostar.starid.eval_starid",
    "loop": "gyrostar.hil.eval_loop",
}


def configure(parser) -> None:
    group.add_targets(parser, TARGETS, dest="target")


run = group.run_target
