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


class StatusPanel(StatusLine):
    """The one-screen panel of ``gyrostar run`` on a terminal (rich Live on stderr, ~4 redraws a
    second from the loop thread between steps, its CPU outside the loop's figures like the
    line's): mode and time in it, stars tracked and identified, rate, attitude 1σ from the
    covariance (and the error against the truth in simulation), frame rate, exposure → output
    latency, link utilisation, overruns, samples lost, elapsed and remaining time."""

    def __init__(self, loop, enabled: bool = True, period_s: float = 0.25):
        self.loop = loop
        self._frames0: tuple[float, int] | None = None
        self._rate_hz: float | None = None
        super().__init__(enabled=enabled, period_s=period_s)

    def update(self, rec, truth=None, step_us: float | None = None, overruns: int = 0,
               duration_s: float | None = None, force: bool = False, t0: float = 0.0) -> None:
        if not self.enabled or rec is None or not (force or self.due()):
            return
        self._last = time.monotonic()
        self._live.update(self.render_panel(rec, truth, step_us, overruns, duration_s, t0), refresh=True)

    def figures(self, rec, t0: float = 0.0) -> dict:
        """What the panel shows besides the output record: from the loop's counters and meters."""
        loop = self.loop
        c = loop.counters()
        t = float(rec["t"])
        changes = c.get("mode_changes") or []
        since = changes[-1][0] if changes else t0
        if self._frames0 is None or t - self._frames0[0] >= 1.0:
            if self._frames0 is not None and t > self._frames0[0]:
                self._rate_hz = (c["frames"] - self._frames0[1]) / (t - self._frames0[0])
            self._frames0 = (t, c["frames"])
        out = {"time_in_mode_s": t - since, "frames_hz": self._rate_hz, "samples_lost": c["samples_lost"],
               "frames": c["frames"]}
        if getattr(loop, "streaming", False):
            s = loop.stream_summary()
            out["exposure_to_output_ms"] = s.get("exposure_to_output_ms_p50")
            out["link_utilisation"] = loop.head.stats().get("link_utilisation")
        return out

    def render_panel(self, rec, truth=None, step_us=None, overruns=0, duration_s=None, t0: float = 0.0):
        from rich.panel import Panel
        from rich.table import Table

        from ..loop.record import sigma

        def f(v, fmt, unit=""):
            return "n/a" if v is None or v != v else format(v, fmt) + unit

        fig = self.figures(rec, t0)
        mode = MODE_NAMES.get(int(rec["mode"]), "?")
        n = int(rec["n_stars"])
        ident = int(np.count_nonzero(rec["star_id"][:n] >= 0))
        rate = np.degrees(rec["omega"])
        s1 = sigma(rec["cov"][:3, :3]) * ARCSEC
        elapsed = float(rec["t"]) - t0
        tab = Table.grid(padding=(0, 2))
        tab.add_column(style="bold")
        tab.add_column()
        tab.add_row("mode", f"[{_MODE_STYLE.get(mode, 'white')}]{mode}[/] for {fig['time_in_mode_s']:.1f} s")
        tab.add_row("stars", f"{n} tracked, {ident} identified")
        tab.add_row("rate", f"{rate[0]:+7.3f} {rate[1]:+7.3f} {rate[2]:+7.3f} °/s (x y z)")
        tab.add_row("attitude 1σ", f"{s1[0]:6.2f} {s1[1]:6.2f} {s1[2]:7.2f} ″ (x y roll, covariance)")
        if truth is not None:
            e = quat_error_angles_many(rec["q"][None, :], truth["q"][None, :])[0] * ARCSEC
            tab.add_row("error", f"{e[0]:+6.2f} {e[1]:+6.2f} {e[2]:+7.2f} ″ (x y roll, simulator truth)")
        tab.add_row("frames", f"{f(fig['frames_hz'], '.1f', ' Hz')}, exposure → output "
                              f"{f(fig.get('exposure_to_output_ms'), '.1f', ' ms')} (p50)")
        lu = fig.get("link_utilisation")
        tab.add_row("link", f"{f(None if lu is None else 100 * lu, '.1f', ' %')} used")
        tab.add_row("loop", f"overruns {overruns}, samples lost {fig['samples_lost']}"
                            + (f", step {step_us:.0f} µs" if step_us is not None else ""))
        left = f", {max(duration_s - elapsed, 0.0):.1f} s left" if duration_s else ""
        tab.add_row("time", f"{elapsed:.1f} s{f' of {duration_s:.0f} s' if duration_s else ''}{left}")
        return Panel(tab, title="gyrostar run", expand=False)
