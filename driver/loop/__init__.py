"""The coupled 400/100 Hz loop and its outputs.

* :mod:`.record`    — the output record (numpy structured dtype), modes and quality flags
* :mod:`.sinks`     — output sinks: callback, recorder, UDP datagrams on loopback
* :mod:`.scheduler` — drift-free periodic scheduling on the monotonic clock, overruns,
  optional SCHED_FIFO and CPU affinity
* :mod:`.warmup`    — numba start-up: compile or load every hot function, timed
* :mod:`.coupled`   — the loop itself: gyro FIFO → predict, windows → head → centroid →
  update, star identification, attitude; ACQUIRE → TRACK → COAST
* :mod:`.stats`     — run statistics (attitude error against truth, latency, modes)
"""
