"""The live status line of ``gyrostar run`` (rich, on stderr, ~4 updates per second)."""

from __future__ import annotations

import time

import numpy as np

from ..loop.record import MODE_NAMES
from .analysis import ARCSEC, quat_error_angles_many

_MODE_STYLE = {"ACQUIRE": "yellow", "TRACK": "green", "COAST": "magenta"}


class StatusLine:
    """``update(last_output, truth_row, loop_stats)`` redraws at most every ``period_s``."""

    def __init__(self, enabled: bool = True, period_s: float = 0.25):
        self.enabled = enabled
        self.period_s = period_s
        self._last = 0.0
        self._live = None
        if enabled:
            from rich.console import Console
            from rich.live import Live

            # refreshed from the loop thread only (no rich refresh thread competing for the GIL)
            self._live = Live("", console=Console(stderr=True), auto_refresh=False, transient=False)
            self._live.start()

    def due(self) -> bool:
        """Whether the next :meth:`update` would redraw (a caller computes its truth row only then)."""
        return self.enabled and time.monotonic() - self._last >= self.period_s

    def update(self, rec, truth=None, step_us: float | None = None, overruns: int = 0,
               duration_s: float | None = None, force: bool = False, t0: float = 0.0) -> None:
        if not self.enabled or rec is None or not (force or self.due()):
            return
        self._last = time.monotonic()
        self._live.update(self.render(rec, truth, step_us, overruns, duration_s, t0), refresh=True)

    @staticmethod
    def render(rec, truth=None, step_us=None, overruns=0, duration_s=None, t0: float = 0.0) -> str:
        mode = MODE_NAMES.get(int(rec["mode"]), "?")
        rate = np.degrees(rec["omega"])
        t = f"t {rec['t'] - t0:6.2f}s" + (f"/{duration_s:.0f}" if duration_s else "")
        parts = [t, f"[{_MODE_STYLE.get(mode, 'white')}]{mode:7s}[/]", f"stars {int(rec['n_stars']):2d}",
                 f"rate [{rate[0]:+6.2f} {rate[1]:+6.2f} {rate[2]:+6.2f}]°/s"]
        if truth is not None:
            e = quat_error_angles_many(rec["q"][None, :], truth["q"][None, :])[0] * ARCSEC
            parts.append(f"err x/y/roll {e[0]:+7.1f} {e[1]:+7.1f} {e[2]:+8.1f}″")
        if step_us is not None:
            parts.append(f"step {step_us:6.0f}µs")
        parts.append(f"overruns {overruns}")
        return "  ".join(parts)

    def close(self) -> None:
        if self._live is not None:
            self._live.stop()
            self._live.console.print()      # end the status line before the summary
            self._live = None
