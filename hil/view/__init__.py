"""The live view of a run or a replay (rerun): frames, windows, identified stars, attitude.

Ground code: it needs the simulator's truth in simulation and is never imported by the
flight package. :mod:`.feed` (options, the bounded hand-over from the log writer, the view
process and rerun's web server), :mod:`.worker` (the view process), :mod:`.decode` (log
records → what is shown), :mod:`.rrlog` (the rerun entities), :mod:`.names` (star labels),
:mod:`.read` (a saved recording read back with rerun's dataframe API).
"""
