"""Star identification (SPEC §2, paper 001).

* :mod:`.index` — catalog index: stars, navigation stars, star pairs with a Mortari
  k-vector (:mod:`.kvector`), neighbour tables, voxel cone queries; cached files.
* :mod:`.pyramid` — Pyramid lost-in-space identification (Mortari et al. 2004).
* :mod:`.grid` — grid patterns (Padgett & Kreutz-Delgado 1997) and the lost-in-space
  grid baseline with its pattern database.
* :mod:`.extended` — extended grid tracking (paper 001) and the extended-image triangle
  baseline.
* :mod:`.verify` — QUEST residual verification shared by every method.
* :mod:`.star_check` — per-star χ² check (position, magnitude) after the solution.
* :mod:`.tracker` — lost-in-space → tracking → lost state machine.

Synthetic star lists live in :mod:`gyrostar.mocks.star_lists`; ``gyrostar eval starid``,
its figure sweeps and the optional peers in :mod:`gyrostar.hil.evaluation`.

Heavy modules are imported on use: ``from gyrostar.starid.pyramid import Pyramid``.
"""
