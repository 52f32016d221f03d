"""What the loop measures of itself: host time in the 400 Hz path, how long samples wait
in the FIFO, exposure → output, the frame rate.

* The 400 Hz path after the FIFO read (filter kernel, output stage, sinks): host seconds,
  wall and the loop thread's CPU (:meth:`LoopMeters.add_path`), per gyro sample in
  :meth:`LoopMeters.us_per_sample`.
* Sample age at its step (s, the loop's clock: step start − sample stamp): the wait in the
  FIFO that a watermark above 1 adds to every output but the newest.
* Exposure → output (s, the loop's clock): a frame's mid-exposure to the first output
  that holds its update.
* The mid-exposure times of the first and last frame used: the frame rate.

The two distributions are kept in rings of the latest ``keep`` values (written with
array copies, never per value); :meth:`LoopMeters.summary` gives their medians and 99th
percentiles in ms.
"""

from __future__ import annotations

import math

import numpy as np

KEEP = 1 << 16    # values kept per distribution (164 s of samples at 400 Hz)


def ring_put(ring: np.ndarray, count: int, values: np.ndarray) -> int:
    """Write ``values`` into ``ring`` after the ``count`` written so far (wrapping round);
    returns the new count. The ring's first ``min(count, len(ring))`` entries are the kept ones."""
    i = count % len(ring)
    m = min(len(values), len(ring) - i)
    ring[i:i + m] = values[:m]
    ring[:len(values) - m] = values[m:]
    return count + len(values)


class LoopMeters:
    def __init__(self, keep: int = KEEP):
        self.path_s = 0.0          # host s in the 400 Hz path after the FIFO read
        self.path_cpu_s = 0.0      # ... its CPU seconds on the loop's thread (without other threads' turns)
        self.age = np.zeros(keep)  # ring: step start − sample stamp of each output (s)
        self.n_age = 0
        self.e2o = np.zeros(keep)  # ring: mid-exposure → first output holding the frame's update (s)
        self.n_e2o = 0
        self.frame_t = [math.nan, math.nan]   # mid-exposure of the first and last frame used (s)

    def add_path(self, wall_s: float, cpu_s: float) -> None:
        self.path_s += wall_s
        self.path_cpu_s += cpu_s

    def sample_ages(self, ages: np.ndarray) -> None:
        """How old this step's samples were when it began (s)."""
        self.n_age = ring_put(self.age, self.n_age, ages)

    def exposure_to_output(self, lat: np.ndarray) -> None:
        """Frames whose update an output now holds: their mid-exposure → that output (s)."""
        self.n_e2o = ring_put(self.e2o, self.n_e2o, lat)

    def frame_used(self, t_mid: float) -> None:
        """A frame exposed at mid-exposure ``t_mid`` (s) updated the filter."""
        if self.frame_t[0] != self.frame_t[0]:
            self.frame_t[0] = t_mid
        self.frame_t[1] = t_mid

    def us_per_sample(self, samples: int, wall: bool = False) -> float | None:
        """Host µs per gyro sample in the 400 Hz path (CPU of the loop's thread, or ``wall``
        with the turns other threads took inside it); None before the first sample."""
        if not samples:
            return None
        return (self.path_s if wall else self.path_cpu_s) / samples * 1e6

    def summary(self, frames: int) -> dict:
        """Sample age at its step and exposure → output (p50, p99, ms) and, from ``frames``
        frames used, the frame rate (Hz); each only once there is something to say."""
        out: dict = {}
        n = min(self.n_age, len(self.age))
        if n:
            age = np.maximum(self.age[:n], 0.0) * 1e3      # the ring's order does not matter here
            out["sample_age_at_step_ms_p50"] = float(np.median(age))
            out["sample_age_at_step_ms_p99"] = float(np.percentile(age, 99))
        n = min(self.n_e2o, len(self.e2o))
        if n:
            lat = self.e2o[:n] * 1e3
            out["exposure_to_output_ms_p50"] = float(np.median(lat))
            out["exposure_to_output_ms_p99"] = float(np.percentile(lat, 99))
        t0, t1 = self.frame_t
        if frames > 1 and t1 > t0:
            out["frame_rate_hz"] = (frames - 1) / (t1 - t0)
        return out
