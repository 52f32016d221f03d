"""The coupled 400/100 Hz loop: one module per stage, composed by :mod:`.coupled`.

* :mod:`.coupled`         — the loop: gyro FIFO → predict, windows → head → centroid →
  update, star identification, attitude; ACQUIRE → TRACK ⇄ COAST
* :mod:`.attitude_filter` — MEKF state and attitude history (:mod:`.kernels`,
  :mod:`.update_kernel`, :mod:`.frame_kernel`: its numba calls)
* :mod:`.tracks`          — tracked stars and the next exposure's windows (:mod:`.image_kernels`)
* :mod:`.image`           — centroiding on a measuring thread, lost in space (:mod:`.acquire`)
* :mod:`.modes`           — the pure mode machine; :mod:`.mode_keeper` — the mode and the
  outputs' image flags from each frame's outcome (:mod:`.stream_images`: which streamed
  outcomes it hears)
* :mod:`.step_schedule`   — when the loop steps; :mod:`.scheduler` — the runner's periodic
  ticks, overruns, SCHED_FIFO and CPU affinity
* :mod:`.head_link`       — the head link up or down, reconnects; :mod:`.stream_plans` — a
  streaming head's window plans; :mod:`.linkbudget` — pixels and frame rate per link
* :mod:`.outputs`, :mod:`.sinks`, :mod:`.record` — the 400 Hz output records and where they go
* :mod:`.floor`           — the run's steady-state attitude floor
* :mod:`.meters`          — host time in the 400 Hz path, sample age, exposure → output
* :mod:`.warmup`, :mod:`.wakeup_probe` — numba start-up; the host's late wake-ups
"""
