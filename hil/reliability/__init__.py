"""Reliability campaigns: faults injected into the flatsat, star-identification safety,
recorder crash safety, the Python decoder/config fuzz campaign, and the soak.

* :mod:`.campaign` — run the coupled loop on the simulated flatsat under a timed fault
  schedule, keeping a compact preallocated trace (no growth with run length), RSS samples
  and overrun counts.
* :mod:`.linkfaults` — the 30 s link-fault run (corruption, drops, garbage, disconnect).
* :mod:`.soak` — an hour (or ``--duration``) of flatsat time with random faults.
* :mod:`.starid_safety` — trials with false stars and magnitude noise through the tracker.
* :mod:`.recorder_kill` — SIGKILL a recording process at random points and check the logs.

Every campaign is a ``python -m gyrostar.hil.reliability.<name>`` command printing one JSON object
(the figures in ``docs/RELIABILITY.md``).
"""
