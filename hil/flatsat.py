"""Build a flatsat from its config: devices (simulated or real), driver, loop, truth.

Two halves, kept apart so that replay can reuse the second:

* **devices** — the register bus of the gyro and the packet link of the head. On the
  simulated flatsat: the simulator (:mod:`gyrostar.mocks`) behind a BMI088 register
  model on a fake SMBus, and the head emulator or the firmware host program on a pty,
  all on one clock (simulated, or real time with ``--realtime``). On a real flatsat:
  ``/dev/i2c-N`` or ``/dev/spidevB.D`` and a serial port.
* **driver** (:func:`make_driver`) — the gyro driver and the head client built on
  whatever bus/link/clock they are given: the live devices wrapped by the recording taps,
  or the replay taps answering from a log. Same code both ways, so replay is exact.
"""

from __future__ import annotations

import bisect
import dataclasses
import logging
import math
import threading
import time
from dataclasses import dataclass

import numpy as np

from ..errors import ConfigError, DeviceError
from ..recording import logfile as lf
from ..recording import taps
from . import config as hc
from .headport import CH_HEAD_CLOCK, CH_POLL, CH_RECONNECT, POLL

log = logging.getLogger(__name__)
DEG = math.pi / 180.0


# ---------------------------------------------------------------------------- truth
def scenario_profile(scen: hc.Scenario):
    """The scenario's body-rate profile (a :class:`gyrostar.mocks.trajectory.RateProfile`)."""
    from ..mocks.trajectory import LinearSegments

    t, t0, t1, w0, w1 = 0.0, [], [], [], []
    for seg in scen.segments:
        t0.append(t)
        t += seg.seconds
        t1.append(t)
        w0.append(np.asarray(seg.rate_dps, float) * DEG)
        w1.append(np.asarray(seg.rate_end_dps, float) * DEG if seg.rate_end_dps is not None else w0[-1])
    if not t0:
        t0, t1, w0, w1 = [0.0], [math.inf], [np.zeros(3)], [np.zeros(3)]
    return LinearSegments(t0, t1, w0, w1)


class Truth:
    """Attitude, body rate and gyro bias truth of a simulated run at host times (s).

    Scenario time is host time minus ``t_origin`` (the run's start on the host clock).
    """

    def __init__(self, scen: hc.Scenario, gyro_stream, t_origin: float = 0.0):
        """``gyro_stream``: the run's simulated gyro (:class:`gyrostar.mocks.gyro_truth.GyroStream`)."""
        from ..attitude import quat_from_boresight

        self.profile = scenario_profile(scen)
        self.q0 = np.asarray(quat_from_boresight(scen.ra_deg * DEG, scen.dec_deg * DEG, scen.roll_deg * DEG))
        self.gyro = gyro_stream
        self.t_origin = t_origin
        self._cache: dict = {}
        self._lock = threading.Lock()
        self.on_restart: list = []
        # the integrator's compiled kernel loaded (or compiled) now, not at the first truth
        # query while the loop runs
        from ..mocks.trajectory import integrate

        integrate(self.q0, self.profile, np.array([0.0, 1e-3]))

    def restart(self, t_origin: float) -> None:
        """Scenario time 0 is now ``t_origin`` (host s): call just before the loop starts."""
        with self._lock:
            self.t_origin = float(t_origin)
            self._cache.clear()
        for fn in self.on_restart:
            fn(self.t_origin)

    def q_at(self, t_host: float, who: str = "") -> np.ndarray:
        """Attitude at one host time, integrated on from this caller's previous query."""
        from ..mocks.trajectory import integrate_to

        ts = max(float(t_host) - self.t_origin, 0.0)
        with self._lock:
            t0, q0 = self._cache.get(who, (0.0, self.q0))
            if ts < t0:
                t0, q0 = 0.0, self.q0
            q = integrate_to(q0, self.profile, t0, ts) if ts > t0 else q0
            self._cache[who] = (ts, q)
        return q

    def rates(self, t_host: np.ndarray) -> np.ndarray:
        return self.profile.rate(np.maximum(np.asarray(t_host, float) - self.t_origin, 0.0))

    def rows(self, t: np.ndarray) -> np.ndarray:
        from ..loop.record import TRUTH_DTYPE
        from ..mocks.trajectory import integrate

        t = np.asarray(t, dtype=np.float64)
        out = np.zeros(len(t), TRUTH_DTYPE)
        out["t"] = t
        if not len(t):
            return out
        ts = np.maximum(t - self.t_origin, 0.0)
        order = np.argsort(ts, kind="stable")
        q = integrate(self.q0, self.profile, np.concatenate([[0.0], ts[order]]))[1:]
        out["q"][order] = q
        out["omega"] = self.profile.rate(ts)
        g = self.gyro
        out["bias"] = g.bias(np.maximum(np.round(ts * g.odr_hz).astype(np.int64) - 1, 0))
        return out

    def at(self, t: float):
        from ..loop.record import TRUTH_DTYPE

        row = np.zeros(1, TRUTH_DTYPE)[0]
        row["t"] = t
        row["q"] = self.q_at(t, "status")
        return row


def simulated_gyro(cfg: hc.FlatsatConfig, scen: hc.Scenario, seed: int):
    """The simulated gyro's output for a run of any length: the scenario's rate profile (held
    at its last rate after the scenario ends) through the configured error model, ideal
    sampling (the register model quantises at the range the driver sets)."""
    from ..mocks.gyro_truth import GyroStream, gyro_params

    gp = gyro_params(scen.gyro_errors or cfg.sim.gyro_errors, range_dps=0.0, odr_hz=float(cfg.gyro.odr_hz),
                     **scen.gyro_overrides)
    from ..mocks.trajectory import Rotated

    sensed = Rotated(scenario_profile(scen), true_mounting(scen.truth).T)    # camera → gyro axes
    return GyroStream(sensed, gp, seed=seed)


class ScenarioScene:
    """The head emulator's scene: attitude at exposure start and the body rates over it."""

    def __init__(self, truth: Truth, exposure_s: float, n_rates: int = 8):
        self.truth = truth
        self.exposure_s = exposure_s
        self.n = n_rates
        self._mid = (np.arange(n_rates) + 0.5) * exposure_s / n_rates    # segment midpoints from the start (s)

    def at(self, t_host: float):
        q = self.truth.q_at(t_host, "scene")
        return q, self.truth.rates(t_host + self._mid)

    def env_time(self, t_host: float) -> float:
        """Scenario time (s) of host time ``t_host``: the orbit environment's clock."""
        return float(t_host) - self.truth.t_origin


# ---------------------------------------------------------------------------- driver
def loop_params(cfg: hc.FlatsatConfig, e_per_dn: float | None = None, scen: hc.Scenario | None = None,
                camera_sigma_px: float | None = None, scale_calibrated: bool = False,
                camera_bias_px: tuple = (0.0, 0.0)):
    """The loop's parameters from the config; a simulated flatsat's detector gain, gyro
    angle random walk and gyro low-pass cut-off come from its simulator models (what a
    calibration or the datasheet would give); ``camera_sigma_px`` the camera-model σ
    (:func:`camera_sigma`; default the config's). The rate-proportional gyro error is the
    config's (what is left after a scale calibration) on a real gyro or under a [gyro_scale]
    calibration (``scale_calibrated``), else a simulated part's own. ``camera_bias_px``: the
    principal point's 1σ (:func:`camera_bias`), a pointing bias reported beside the covariance."""
    from ..loop.coupled import LoopParams

    lc = cfg.loop
    arw = lc.gyro_arw_deg_rts * DEG
    delay = lc.gyro_delay_ms * 1e-3
    lowpass = lc.gyro_lowpass_hz
    rate_error = lc.gyro_rate_error_ppm * 1e-6
    bias_prior = lc.gyro_bias_prior_dps * DEG
    if cfg.simulated:
        from ..mocks.gyro_truth import gyro_params

        gp = gyro_params((scen.gyro_errors if scen is not None else "") or cfg.sim.gyro_errors)
        # white rate noise of one-sided density n → angle random walk N = n/√2; the per-sample
        # white term (°/h per sample at the ODR) adds σ²/ODR to N²
        n2 = (gp.noise_density_dps_rthz * DEG) ** 2 / 2.0 + (gp.white_sigma_dph * DEG / 3600.0) ** 2 / gp.odr_hz
        if n2 > 0:
            arw = math.sqrt(n2)
        lowpass = gp.filter_hz
        # scale factor and cross-axis errors the simulated part carries (none in a calibrated
        # set), unless a [gyro_scale] calibration takes them out: then what it leaves (config)
        if not scale_calibrated:
            rate_error = math.hypot(gp.scale_factor_sigma_ppm * 1e-6, gp.misalignment_sigma_mrad * 1e-3)
        # the offset the part may have, as a 1σ prior wide enough for it: 3x its fixed value or
        # 3σ of its per-part draw (what a calibration's uncertainty would give)
        bias_prior = 3.0 * max(max(abs(v) for v in gp.bias_dps), gp.bias_sigma_dps, 0.002) * DEG

    def scen_or_config(key):             # a scenario's loop key overrides the config's when > 0
        v = getattr(scen, key) if scen is not None else 0
        return v if v > 0 else getattr(lc, key)

    max_stars = scen_or_config("max_stars")
    if max_stars < lc.min_stars:
        raise ConfigError(f"scenario '{scen.name}': max_stars = {max_stars} is below loop.min_stars = {lc.min_stars}")
    p = LoopParams(frame_hz=lc.frame_hz, exposure_s=cfg.head.exposure_ms * 1e-3, window_k=lc.window_k,
                   max_stars=max_stars, min_stars=lc.min_stars, coast_timeout_s=scen_or_config("coast_timeout_s"),
                   acquire_every_s=scen_or_config("acquire_every_s"), mag_limit=lc.mag_limit,
                   confirm_images=lc.confirm_images,
                   wrong_id_rejects=lc.wrong_id_rejects, neighbour_sep_px=lc.neighbour_sep_px,
                   reconnect_every_s=lc.reconnect_every_s, head_timeouts_lost=lc.head_timeouts_lost,
                   stream_few_frames=lc.stream_few_frames, stream_gap_frames=lc.stream_gap_frames, gyro_arw=arw,
                   gyro_delay_s=delay, gyro_lowpass_hz=lowpass, gyro_rate_error=rate_error,
                   max_track_rate=lc.max_track_rate_dps * DEG,
                   bias_prior=bias_prior,
                   camera_sigma_px=lc.camera_sigma_px if camera_sigma_px is None else camera_sigma_px,
                   camera_bias_px=tuple(camera_bias_px))
    if e_per_dn:
        p.e_per_dn = e_per_dn
    return p


def make_gyro(cfg: hc.FlatsatConfig, regs, clock):
    """The gyro driver on a RegisterBus, configured (range, ODR, FIFO watermark)."""
    from ..gyro import Bmi088Gyro, L3gd20hGyro

    g = cfg.gyro
    cls = Bmi088Gyro if g.model == "bmi088" else L3gd20hGyro
    gyro = cls(regs, clock=clock)
    gyro.configure(odr_hz=g.odr_hz, range_dps=g.range_dps, watermark=g.fifo_watermark)
    return gyro


def make_head(cfg: hc.FlatsatConfig, link, clock, reconnect=None, head_clock=None, poll_log=None,
              replay_polls=None, replay_reconnects=None, fast: bool = False, replay_records=None, lockstep=None):
    """The head port the loop drives (see :mod:`gyrostar.hil.headport`), on a packet link:
    a streaming port (:mod:`gyrostar.hil.streamport`) with ``head.mode = "stream"``.
    ``lockstep``: fast mode's schedule, which runs the port's jobs (and stream turns) at once
    on their own simulated time (no worker thread)."""
    from ..transport.linkrate import PRESETS
    from .headport import HeadPort

    if lockstep is not None:
        lockstep.inline_jobs = True
    if cfg.head.mode == "stream":
        from ..protocol.defs import PixelFormat
        from .streamport import StreamPort, StreamReplay

        replay = StreamReplay(replay_records) if replay_records is not None else None
        return StreamPort(link, clock, pixel_format=int(PixelFormat[cfg.head.pixel_format.upper()]),
                          frame_hz=cfg.loop.frame_hz, link_preset=PRESETS.get(cfg.head.link), replay=replay,
                          timeout_s=cfg.head.timeout_s, retries=cfg.head.retries,
                          exposure_s=cfg.head.exposure_ms * 1e-3, gain=cfg.head.gain, reconnect=reconnect,
                          head_clock=head_clock, poll_log=poll_log, replay_polls=replay_polls,
                          replay_reconnects=replay_reconnects, acquire=cfg.head.acquire,
                          stream_clock=lockstep, inline=lockstep)
    return HeadPort(link, clock, timeout_s=cfg.head.timeout_s, retries=cfg.head.retries,
                    exposure_s=cfg.head.exposure_ms * 1e-3, gain=cfg.head.gain, reconnect=reconnect,
                    head_clock=head_clock, poll_log=poll_log, replay_polls=replay_polls,
                    replay_reconnects=replay_reconnects, inline=lockstep, acquire=cfg.head.acquire,
                    link_preset=PRESETS.get(cfg.head.link))


def star_index(cfg: hc.FlatsatConfig, camera):
    from ..starid.index import load_index

    diag = 2.0 * math.degrees(math.atan(0.5 * math.hypot(camera.width_px, camera.height_px)
                                        / camera.focal_length_px))
    return load_index(cfg.sim.catalog, cfg.loop.mag_limit, max_sep_deg=math.ceil(diag * 10 + 1) / 10)


def camera_sigma(cfg: hc.FlatsatConfig, scen: hc.Scenario, calib) -> float:
    """The loop's camera-model σ (px, added to every star's centroid σ): the largest of the
    [camera] calibration's fit residual (``camera.residual_rms_px``), ``loop.camera_sigma_px``
    and the scenario's ``camera_sigma_px``. Each is a floor on how far the model may put a
    star: raising ``loop.camera_sigma_px`` always takes effect, and no config lowers what a
    fit measured. With a [camera] table the σ is never 0: a table without a fit residual (a
    lens's nominal values) and no configured σ is a :class:`ConfigError` naming both keys.
    Without a table, 0 means an exact model (the simulator's preset)."""
    configured = max(float(scen.camera_sigma_px), float(cfg.loop.camera_sigma_px))
    if calib is None or calib.cal is None or calib.cal.camera is None:
        return configured
    sigma = max(float(calib.cal.camera.residual_rms_px), configured)
    if not sigma > 0:
        raise ConfigError(f"calibration {calib.path}: its [camera] table has no fit residual "
                          "(camera.residual_rms_px = 0, nominal values) and loop.camera_sigma_px is 0: set "
                          "loop.camera_sigma_px to that model's uncertainty (px; 2.0 for a lens's nominal values, "
                          "docs/HARDWARE.md step 5)")
    return sigma


def camera_bias(calib) -> tuple[float, float]:
    """1σ (px, column and row) of the [camera] calibration's principal point, (0, 0) without
    one: the camera model's error common to every star (a pointing bias)."""
    if calib is not None and calib.cal is not None and calib.cal.camera is not None:
        sx, sy = calib.cal.camera.principal_point_sigma_px
        return float(sx), float(sy)
    return 0.0, 0.0


def gyro_scale_calibrated(calib) -> bool:
    """The run applies a [gyro_scale] calibration (scale factors and misalignment)."""
    return calib is not None and calib.cal is not None and calib.cal.gyro_scale is not None


def make_loop(cfg, clock, gyro, head, camera, sinks, lat_clock=None, e_per_dn=None, irq=None, scen=None,
              camera_sigma_px=None, scale_calibrated=False, camera_bias_px=(0.0, 0.0), cpu_clock=time.thread_time):
    from ..catalog import deepest_limit, load_catalog
    from ..loop.coupled import CoupledLoop
    from ..starid.blends import BLEND_DMAG, BLEND_PX, blended
    from ..starid.faint import DEPTH_MAG
    from ..starid.lost_in_space import build_pyramid

    idx = star_index(cfg, camera)
    # the sky holds stars beyond the index's limit: a lost-in-space label next to one is dropped
    deep = load_catalog(cfg.sim.catalog, deepest_limit(cfg.sim.catalog, idx.mag_limit + max(DEPTH_MAG, BLEND_DMAG)))
    ident = build_pyramid(camera, index=idx, faint_catalog=deep.brighter_than(idx.mag_limit + DEPTH_MAG))
    # stars whose spot is a blend with a neighbour: tracked only when too few others are
    blends = blended(idx, deep, BLEND_PX / camera.focal_length_px, BLEND_DMAG)
    budget = None
    if getattr(head, "streaming", False) and cfg.head.link != "none":
        from ..loop.linkbudget import LinkBudget
        from ..transport.linkrate import preset

        budget = LinkBudget(preset(cfg.head.link), cfg.loop.frame_hz)
    params = loop_params(cfg, e_per_dn, scen, camera_sigma_px, scale_calibrated, camera_bias_px)
    return CoupledLoop(params, clock, gyro, head, camera, idx, ident, sinks,
                       lat_clock=lat_clock, irq=irq, link_budget=budget, blended=blends, cpu_clock=cpu_clock)


# ---------------------------------------------------------------------------- flatsat
@dataclass
class Flatsat:
    cfg: hc.FlatsatConfig
    scen: hc.Scenario
    camera: object
    clock: object              # the recording clock the driver and loop use
    base_clock: object         # the underlying clock (simulated or monotonic)
    gyro: object
    head: object
    truth: Truth | None
    simulated_clock: bool
    wiring: dict
    lat_clock: object = None
    e_per_dn: float | None = None
    faults: object = None
    closers: tuple = ()
    irq: object = None
    device_truth: Truth | None = None   # the emulated devices' scenario (also on a half-real flatsat)
    calibration: object = None          # gyrostar.calibration.apply.RunCalibration in use
    true_camera: object = None          # the simulated head's real optics (may differ from ``camera``)
    device_cpu: DeviceCpu | None = None  # CPU the loop's thread spends inside in-process emulated devices
    environment: object = None          # the emulated head's orbit environment (gyrostar.mocks.environment)
    sim_preset: object = None           # the emulated head's simulator preset (true camera)

    def start_scenario(self, t0: float) -> None:
        """Scenario time 0 of the emulated devices is host time ``t0`` (just before the loop starts)."""
        if self.device_truth is not None:
            self.device_truth.restart(t0)
    lockstep: object = None    # fast mode: the lock-step schedule (gyrostar.hil.lockstep.Lockstep)

    def make_loop(self, sinks):
        return make_loop(self.cfg, self.clock, self.gyro, self.head, self.camera, sinks, self.lat_clock,
                         self.e_per_dn, self.irq, self.scen, camera_sigma(self.cfg, self.scen, self.calibration),
                         gyro_scale_calibrated(self.calibration), camera_bias(self.calibration),
                         cpu_meter_clock(self.simulated_clock))

    def clock_now(self) -> float:
        return self.base_clock.now()

    def clock_advance(self, dt: float) -> None:
        self.base_clock.sleep(dt)

    def start_faults(self, t0: float) -> None:
        """Real time: the fault plan's own thread applies it; fast mode: :meth:`apply_faults`."""
        if self.faults is not None and self.lockstep is None:
            self.faults.start(t0, self.base_clock)

    def apply_faults(self, t: float) -> None:
        """The faults and eclipses due at scenario time ``t`` (s), applied by the caller (fast
        mode's runner; the reliability campaigns, at each tick)."""
        if self.faults is not None:
            self.faults.apply(t)

    def head_faults_due(self, t: float) -> bool:
        """:meth:`apply_head_faults` at scenario time ``t`` (s) would switch a head fault or an eclipse."""
        return self.faults is not None and self.faults.head_events_due(t)

    def apply_head_faults(self, t: float) -> None:
        """Fast mode: the head's faults and eclipses due at scenario time ``t`` (s), from a
        head job that runs ahead of the loop on its own time line."""
        if self.faults is not None:
            self.faults.apply_head(t)

    def loop_stalled(self, t: float) -> bool:
        return self.faults is not None and self.faults.stalled(t)

    def truth_at(self, t: float):
        return self.truth.at(t) if self.truth is not None else None

    def truth_rows(self, t: np.ndarray):
        return self.truth.rows(t) if self.truth is not None else None

    def centroid_errors(self, out: np.ndarray) -> np.ndarray | None:
        """[t, du, dv] (px) of tracked stars' output centroids against their true positions
        (every 10th TRACK output: :func:`analysis.tracked_centroid_errors`)."""
        if self.truth is None:
            return None
        from ..catalog import load_catalog
        from .analysis import tracked_centroid_errors

        cat = load_catalog(self.cfg.sim.catalog, max(self.cfg.loop.mag_limit, self.cfg.sim.mag_limit))
        return tracked_centroid_errors(out, self.truth.rows, cat.ids, cat.vectors,
                                       (self.true_camera or self.camera).as_array())

    def close(self) -> None:
        if self.faults is not None:
            self.faults.stop()
        for c in self.closers:
            try:
                c()
            except Exception as exc:  # noqa: BLE001 - closing must not hide the run's result
                log.debug("close: %s", exc)


def true_camera(nominal, tr: hc.TrueDevices):
    """The simulated head's real optics: ``nominal`` moved by the scenario's [truth]."""
    return dataclasses.replace(nominal, focal_length_m=nominal.focal_length_m * tr.focal_scale,
                               cx_px=nominal.cx_px + tr.principal_offset_px[0],
                               cy_px=nominal.cy_px + tr.principal_offset_px[1], k1=nominal.k1 + tr.k1)


def true_mounting(tr: hc.TrueDevices) -> np.ndarray:
    """The simulated gyro's real mounting: rotation gyro → camera (3×3) from the rotation vector."""
    from ..calibration.intrinsics import rotvec_dcm

    return rotvec_dcm(np.radians(np.asarray([tr.gyro_rotation_deg], float)))[0]


def load_calibration(cfg: hc.FlatsatConfig, meta: dict | None = None):
    """The run's calibration (:class:`gyrostar.calibration.apply.RunCalibration`): the file of
    ``cfg.calibration``, or on replay the text kept in the log's META."""
    from ..calibration import apply

    if meta is not None:
        return apply.from_meta(meta)
    return apply.load_for_run(cfg.calibration)


def with_hot_pixels(head, calib, camera, wiring: dict):
    """``head`` with the calibration's hot pixels repaired in every readout (itself without any)."""
    hot = calib.hot_pixels()
    if not len(hot):
        return head
    from ..calibration.hot_pixels import HotPixelRepair

    wiring["hot_pixels"] = f"{len(hot)} hot pixels of [dark] repaired in every readout (row-neighbour mean)"
    return HotPixelRepair(head, hot, camera.width_px)


HEAD_FAULTS = ("head-disconnect", "link-corruption", "head-clock-step")
GYRO_FAULTS = ("gyro-nack",)


def emulated_head(cfg: hc.FlatsatConfig) -> bool:
    return cfg.head.kind in ("emulator", "firmware-host")


def emulated_gyro(cfg: hc.FlatsatConfig) -> bool:
    return cfg.gyro.kind == "emulator"


def preflight(cfg: hc.FlatsatConfig, scen: hc.Scenario, simulated_clock: bool = False, devices: bool = True) -> None:
    """Refuse, before anything is opened or compiled, a device mix that cannot work
    (:class:`ConfigError`, exit 2, with the reason) and a real device node that is not
    there (:class:`DeviceError`, exit 3, naming it; ``devices=False`` skips the device nodes,
    for a campaign whose runs are all emulated). ``gyrostar run`` checks them before its run
    folder is made: a missing device leaves no folder and no log.

    Any mix of real and emulated devices is allowed: an emulated device takes its scenario
    from the simulator, a real one its physics from the bench. What cannot work: the gyro
    emulator for a part it does not model, faults injected into a real device, a NACK on the
    emulated gyro's SPI bus, an eclipse on a real sensor, the orbit environment on any head but
    the Python emulator, and a simulated clock with a real device (real devices keep real time).
    """
    import os

    if emulated_gyro(cfg) and cfg.gyro.model != "bmi088":
        raise ConfigError(f"the gyro emulator models the BMI088, not gyro.model = '{cfg.gyro.model}'")
    for f in scen.faults:
        if f.kind in HEAD_FAULTS and not emulated_head(cfg):
            raise ConfigError(f"scenario '{scen.name}' injects '{f.kind}', which needs an emulated head "
                              f"(head.kind = '{cfg.head.kind}')")
        if f.kind in GYRO_FAULTS and not emulated_gyro(cfg):
            raise ConfigError(f"scenario '{scen.name}' injects '{f.kind}', which needs the emulated gyro "
                              f"(gyro.kind = '{cfg.gyro.kind}')")
        if f.kind == "head-clock-step" and cfg.head.kind != "emulator":
            raise ConfigError(f"scenario '{scen.name}' injects 'head-clock-step', which needs the head emulator "
                              f"(head.kind = \"emulator\"; the firmware host program keeps its own clock)")
        if f.kind == "gyro-nack" and emulated_gyro(cfg) and cfg.gyro.emulator_bus == "spi":
            raise ConfigError(f"scenario '{scen.name}' injects 'gyro-nack', which an SPI bus cannot give (it has "
                              "no acknowledge): set gyro.emulator_bus = \"i2c\"")
    if scen.hazards and cfg.head.kind != "emulator":
        raise ConfigError(f"scenario '{scen.name}': the orbit environment ({', '.join(scen.hazards)}) is rendered "
                          f"by the head emulator only (head.kind = \"emulator\"), not by head.kind = '{cfg.head.kind}'")
    if scen.eclipse and not emulated_head(cfg):
        raise ConfigError(f"scenario '{scen.name}' has an eclipse, which needs an emulated head "
                          f"(head.kind = '{cfg.head.kind}')")
    if simulated_clock and not cfg.simulated:
        raise ConfigError("a simulated clock (--fast) needs every device emulated: real devices keep real time")
    if simulated_clock and (cfg.head.kind != "emulator" or cfg.gyro.kind != "emulator"):
        raise ConfigError(f"--fast runs the emulated head and gyro only (this config: head.kind = '{cfg.head.kind}', "
                          f"gyro.kind = '{cfg.gyro.kind}'); run it in real time")
    if cfg.head.kind == "firmware-host" and cfg.head.program and not os.path.isfile(cfg.head.program):
        raise ConfigError(f"head.program = '{cfg.head.program}' does not exist (the firmware's host program; "
                          "empty: the one `make -C firmware host` builds)")
    from ..telemetry.udp import check_destination, resolve

    out = cfg.outputs                       # network outputs the config cannot send: before any run folder
    if out.udp:
        check_destination(out.udp_host, out.udp_port, out.allow_remote, "UDP output")
        resolve(out.udp_host, out.udp_port, "outputs.udp_host", "UDP output")
    if out.space_packets:
        check_destination(out.tm_host, out.tm_port, out.allow_remote, "space-packet output")
        resolve(out.tm_host, out.tm_port, "outputs.tm_host", "space-packet output")
    calib = load_calibration(cfg)           # a missing or invalid file: exit 2 naming it
    camera_sigma(cfg, scen, calib)          # a [camera] table that would give the loop a σ of 0
    if not devices:
        return
    # the device nodes next: a device that is not there is the first thing to fix, before its camera model
    _check_device_nodes(cfg)
    if not emulated_head(cfg):
        calib.camera(None, real_head=True)  # a real head needs the calibrated camera model


def _check_device_nodes(cfg: hc.FlatsatConfig) -> None:
    """:class:`DeviceError` (exit 3) naming a real device node that is not there."""
    import os

    if cfg.head.kind == "serial" and "://" not in cfg.head.url and not os.path.exists(cfg.head.url):
        raise DeviceError(f"head serial port {cfg.head.url} does not exist")
    if cfg.gyro.kind == "i2c" and not os.path.exists(f"/dev/i2c-{cfg.gyro.i2c_bus}"):
        raise DeviceError(f"gyro I2C bus /dev/i2c-{cfg.gyro.i2c_bus} does not exist (i2cdetect -l lists the buses)")
    if cfg.gyro.kind == "spi" and not os.path.exists(f"/dev/spidev{cfg.gyro.spi_bus}.{cfg.gyro.spi_device}"):
        raise DeviceError(f"gyro SPI device /dev/spidev{cfg.gyro.spi_bus}.{cfg.gyro.spi_device} does not exist")


def build(cfg: hc.FlatsatConfig, scen: hc.Scenario, seed: int, realtime: bool, writer, fast: bool = False,
          calibration=None) -> Flatsat:
    """Devices + recording taps + driver for ``cfg`` running ``scen``.

    Real time (default): every device runs on the host monotonic clock; the head emulator's
    and the firmware's exposures take their real time. ``fast``: every device on one
    simulated clock in lock-step (:mod:`gyrostar.hil.lockstep`), the head emulator in this
    process behind the link's line-rate model; needs the emulated head and gyro.
    """
    from ..camera import camera_preset
    from ..clock import MONOTONIC, SimulatedClock
    from ..transport import I2CBus, I2CRegisters

    preflight(cfg, scen, simulated_clock=fast)
    wiring = {}
    irq = None
    preset = scen.preset or cfg.sim.preset
    calib = calibration if calibration is not None else load_calibration(cfg)
    camera = calib.camera(camera_preset(preset) if emulated_head(cfg) else None, real_head=not emulated_head(cfg))
    wiring["calibration"] = calib.describe()
    calibrated = calib.cal is not None and calib.cal.camera is not None
    wiring["camera"] = (f"f {camera.focal_length_px:.2f} px, principal point ({camera.cx_px:.2f}, "
                        f"{camera.cy_px:.2f}) px, k1 {camera.k1:.4g} — "
                        + ("from the calibration file" if calibrated else f"nominal {preset} preset"))
    base = MONOTONIC
    lockstep = None
    if fast:
        from .lockstep import Lockstep

        if cfg.head.kind != "emulator" or cfg.gyro.kind != "emulator":
            raise ConfigError(f"--fast runs the emulated head and gyro only (this config: head.kind = "
                              f"'{cfg.head.kind}', gyro.kind = '{cfg.gyro.kind}'); run it in real time")
        base = SimulatedClock(FAST_T0)
        lockstep = Lockstep(base)
    truth = sim = gsamp = None
    e_per_dn = None
    if emulated_head(cfg) or emulated_gyro(cfg):
        # the emulated devices' world: each emulated device takes only its own part of it
        from ..mocks.sim_preset import load_preset

        sim = load_preset(preset)
        sim = dataclasses.replace(sim, camera=true_camera(sim.camera, scen.truth))
        gsamp = simulated_gyro(cfg, scen, seed)
        truth = Truth(scen, gsamp, t_origin=base.now())
        if not scen.truth.nominal:
            wiring["true_devices"] = f"simulated devices off nominal: {scen.truth}"
        parts = [f"{preset} preset sky and sensor, {cfg.sim.catalog} catalog"] if emulated_head(cfg) else []
        parts += [f"gyro errors '{gsamp.params.name}'"] if emulated_gyro(cfg) else []
        wiring["sky"] = ("simulator: " + ", ".join(parts)
                         + ("" if cfg.simulated else " (emulated devices only; no truth for the run's figures)"))
        if emulated_head(cfg):
            e_per_dn = sim.detector.gain_e_per_adu
    rec_clock = taps.RecordingClock(base, writer) if writer else base
    # fast mode: the head client reads its job's own time (gyrostar.hil.lockstep.Lockstep.now)
    head_base = lockstep if lockstep is not None else base
    head_clock = taps.RecordingClock(head_base, writer, channel=CH_HEAD_CLOCK) if writer else head_base
    closers = []
    faults = FaultPlan(scen)
    device_cpu = None

    # gyro bus
    if cfg.gyro.kind == "emulator":
        from ..mocks.bmi088_model import Bmi088GyroModel
        from ..mocks.fake_rates import StreamRates
        from ..mocks.faults import FaultyBus

        offset = scen.truth.gyro_time_offset_ms * 1e-3   # a sample stamped t measured scenario time t + offset
        model = Bmi088GyroModel(base, StreamRates(gsamp, lambda: truth.t_origin - offset))
        model.truth_log = False    # the run's truth is the simulator's; the model's test log grows ~90 kB/s
        device_cpu = DeviceCpu(cpu_meter_clock(fast))
        # each bus transfer takes its wire time (I2C at the BMI088's fastest clock: 0.73 ms a loop
        # step; SPI at 5 MHz: about 25 µs): on the simulated clock in fast mode, asleep in real
        # time with the interpreter lock released, as in the kernel's ioctl (docs/FLATSAT.md §7,
        # "The emulated gyro's bus")
        from ..mocks.fake_smbus import SleepingWire

        wire = base if fast else SleepingWire()
        if cfg.gyro.emulator_bus == "spi":
            from ..gyro import bmi088

            # SPI needs no NACK injection (it has no acknowledge)
            spi = model.spidev(cfg.gyro.spi_hz)
            spi.clock = wire
            regs = bmi088.spi_registers(device_cpu.wrap(spi), name="emulated spi")
            wiring["gyro"] = (f"BMI088 register model on a fake spidev at {cfg.gyro.spi_hz / 1e6:g} MHz (mocks), "
                              "driven by gyrostar.gyro.Bmi088Gyro")
        else:
            smbus = FaultyBus(model.smbus(cfg.gyro.i2c_address, bus_hz=GYRO_I2C_HZ, wire=wire), clock=base, seed=seed)
            faults.gyro_bus = smbus
            regs = I2CRegisters(I2CBus(device_cpu.wrap(smbus), name="emulated i2c"), cfg.gyro.i2c_address)
            wiring["gyro"] = "BMI088 register model on a fake SMBus (mocks), driven by gyrostar.gyro.Bmi088Gyro"
        irq = device_cpu.wrap(_IrqLine(model))
        if writer:
            irq = taps.RecordingClock(irq, writer, channel=CH_IRQ)
    elif cfg.gyro.kind == "i2c":
        regs = I2CRegisters(I2CBus.open(cfg.gyro.i2c_bus), cfg.gyro.i2c_address)
        wiring["gyro"] = f"{cfg.gyro.model} on /dev/i2c-{cfg.gyro.i2c_bus} address 0x{cfg.gyro.i2c_address:02X}"
    else:
        from ..gyro import bmi088, l3gd20h
        from ..transport import open_spidev

        spi = open_spidev(cfg.gyro.spi_bus, cfg.gyro.spi_device, cfg.gyro.spi_hz)
        mod = bmi088 if cfg.gyro.model == "bmi088" else l3gd20h
        regs = mod.spi_registers(spi, name=f"/dev/spidev{cfg.gyro.spi_bus}.{cfg.gyro.spi_device}")
        wiring["gyro"] = f"{cfg.gyro.model} on /dev/spidev{cfg.gyro.spi_bus}.{cfg.gyro.spi_device}"
    if writer:
        regs = taps.RecordingRegisters(regs, writer, clock=rec_clock)
    gyro = calib.gyro(make_gyro(cfg, regs, rec_clock))
    if gyro is not None and calib.gyro_map() is not None:
        m, b, dt = calib.gyro_map()
        wiring["gyro_calibration"] = (f"ω_camera = M (ω_gyro − b), t_camera = t_gyro + {dt * 1e3:.3f} ms; "
                                      f"b = {np.degrees(b).round(5).tolist()} °/s")

    # head link
    environment = scenario_environment(scen, seed) if emulated_head(cfg) else None
    if environment is not None:
        wiring["environment"] = "orbit environment (gyrostar.mocks.environment): " + ", ".join(scen.hazards)
    open_link, head_wiring, head_closers = _head_devices(cfg, scen, sim, truth, seed, faults, lockstep, environment)
    wiring["head"] = head_wiring
    closers += head_closers
    current = {}

    def connect():
        old = current.get("link")
        if old is not None:
            try:
                old.close()
            except Exception:  # noqa: BLE001 - the old link is already broken
                pass
        link = open_link()
        current["link"] = link
        return taps.RecordingLink(link, writer, clock=rec_clock) if writer else link

    head = make_head(cfg, connect(), rec_clock, reconnect=connect, head_clock=head_clock,
                     poll_log=writer, fast=fast, lockstep=lockstep)
    head = with_hot_pixels(head, calib, camera, wiring)
    closers.insert(0, head.close)
    closers.append(lambda: current["link"].close())
    wiring["loop"] = ("gyrostar.loop.coupled: attitude MEKF (gyrostar.core.mekf) with star-vector updates, "
                      "Pyramid acquisition (gyrostar.starid.pyramid), trajectory windows (gyrostar.core.motion/"
                      "windows), CoG + smeared-PSF centroids (gyrostar.core.centroid)")
    wiring["gyro_time"] = ("FIFO watermark interrupt edges (emulated INT3 line) anchor the sample times"
                           if irq is not None else "FIFO polls bound the sample times (no interrupt line wired)")
    lat_clock = None
    if fast:
        # host compute time from FIFO read to outputs (simulated time stands still in a step)
        lat_clock = taps.RecordingClock(MONOTONIC, writer, channel=lf.CH_LATENCY) if writer else MONOTONIC
        wiring["clock"] = ("simulated clock in lock-step (gyrostar.hil.lockstep): devices, link and loop on "
                           "one time line; the host's compute time is not simulated")
    return Flatsat(cfg, scen, camera, rec_clock, base, gyro, head, truth if cfg.simulated else None,
                   simulated_clock=fast, wiring=wiring, lat_clock=lat_clock, e_per_dn=e_per_dn, faults=faults,
                   closers=tuple(closers), irq=irq, lockstep=lockstep, device_truth=truth, calibration=calib,
                   true_camera=sim.camera if sim is not None else None, device_cpu=device_cpu,
                   environment=environment, sim_preset=sim)


CH_IRQ = 5
FAST_T0 = 1000.0    # s: start of the simulated clock in fast mode
GYRO_I2C_HZ = 400e3  # the emulated gyro's I2C clock: the BMI088's fast mode, its highest


def cpu_meter_clock(fast: bool):
    """The clock the loop's CPU meters read (s). Real time: the thread's CPU time, other
    threads' turns left out. Fast mode: the wall clock — the loop, its emulated devices and
    the head's inline jobs share the lock-step thread and nothing else of the run is busy
    (process CPU ≈ 100 % of one core), so it reads the same time without the system call a
    CPU-time reading costs (µs each on a VM, ~25 per step)."""
    return time.perf_counter if fast else time.thread_time


class DeviceCpu:
    """CPU seconds (``cpu_clock``: thread time; fast mode's wall clock, :func:`cpu_meter_clock`)
    spent inside the in-process emulated gyro — its fake bus, register model and truth — by
    whichever thread called it (the loop's, in a run). A real
    flatsat spends that time in the kernel's I2C/SPI driver and its GPIO edge read instead;
    the run reports it beside the loop's CPU so the flight code's own share is visible."""

    def __init__(self, cpu_clock=time.thread_time):
        self.cpu_s = 0.0
        self.cpu_clock = cpu_clock     # fast mode: the lock-step thread's wall clock (see CoupledLoop)

    def wrap(self, obj):
        """``obj`` with every public method timed into :attr:`cpu_s`."""
        return _Metered(obj, self)


class _Metered:
    def __init__(self, obj, meter: DeviceCpu):
        self._obj = obj
        self._meter = meter

    def __getattr__(self, name):
        attr = getattr(self._obj, name)
        if name.startswith("_") or not callable(attr):
            return attr
        meter = self._meter
        tt = meter.cpu_clock

        def timed(*args, **kwargs):
            c0 = tt()
            try:
                return attr(*args, **kwargs)
            finally:
                meter.cpu_s += tt() - c0

        self.__dict__[name] = timed      # made once: later look-ups find it without __getattr__
        return timed


class _IrqLine:
    """The emulated FIFO-watermark interrupt line: host time of its latest edge (nan: none)."""

    def __init__(self, model):
        self.model = model

    def now(self) -> float:
        t = self.model.watermark_time()
        return float("nan") if t is None else float(t)


def _sim_head(cfg, scen, sim, truth, seed, faults, lockstep, environment=None):
    """The head emulator in this process on a device clock, behind the line-rate link model."""
    from ..catalog import load_catalog
    from ..clock import SimulatedClock
    from ..mocks.head_emulator import HeadEmulator
    from ..mocks.sky import Sky
    from ..transport.linkrate import preset as link_preset
    from .lockstep import SimHead

    cat = load_catalog(cfg.sim.catalog, scen.mag_limit or cfg.sim.mag_limit)
    dev_clock = SimulatedClock(lockstep.clock.now())
    sky = Sky(cat, sim, seed=seed, false_spots=scen.false_spots or None, environment=environment)
    emu = HeadEmulator(sky, ScenarioScene(truth, sim.detector.exposure_s), noise=True,
                       clock=dev_clock)
    # its kernels compiled (cold cache) or loaded now, not at its first frame inside the run
    from ..logs import stage
    from ..loop import warmup

    with stage("compiling the head emulator's kernels (rendering, spot finder; once)", told=warmup.cold_start):
        emu.warm_up(truth.q0)
    from . import render_ahead

    closers = []
    if render_ahead.usable():
        # streamed frames rendered by a forked copy while the loop steps (the same pixels)
        emu.renderer = render_ahead.RenderAhead(emu)
        closers.append(emu.renderer.close)
        renderer = emu.renderer
        lockstep.job_waits = lambda: renderer.wait_s    # the loop's CPU figure leaves the waits out
    head = SimHead(emu, dev_clock, link_preset(cfg.head.link), lockstep)
    head.start()
    faults.head_emulator = head
    where = "its streamed windows rendered ahead in a forked child process, " if emu.renderer is not None else ""
    return (head.open_link, f"Python head emulator (mocks) in process on a simulated clock, {where}link "
            f"{head.preset.description}", [head.stop] + closers)


def _head_devices(cfg, scen, sim, truth, seed, faults, lockstep=None, environment=None):
    """(open_link() -> SerialLink, wiring text, closers) for the configured head."""
    from ..transport import SerialLink

    h = cfg.head
    if lockstep is not None:
        return _sim_head(cfg, scen, sim, truth, seed, faults, lockstep, environment)
    if h.kind == "emulator":
        from .emuproc import EmulatorProcess

        def make():
            # runs in the child process
            from ..catalog import load_catalog
            from ..mocks.head_emulator import HeadEmulator
            from ..mocks.sky import Sky

            cat = load_catalog(cfg.sim.catalog, scen.mag_limit or cfg.sim.mag_limit)
            sky = Sky(cat, sim, seed=seed, false_spots=scen.false_spots or None, environment=environment)
            emu = HeadEmulator(sky, ScenarioScene(truth, sim.detector.exposure_s), noise=True)
            emu.warm_up(truth.q0)        # render once up front (numba load, fixed-pattern noise)
            return emu, truth

        emu = EmulatorProcess(make, link=None if h.link == "none" else h.link)
        emu.start()
        faults.head_emulator = emu
        truth.on_restart.append(emu.set_origin)

        def open_link():
            if not emu.connected:
                raise DeviceError("head emulator is disconnected (pty closed)")
            return SerialLink(emu.path, baudrate=h.baudrate)

        return open_link, (f"Python head emulator (mocks) in a child process, on pty {emu.path} "
                           f"(link {h.link})"), [emu.stop]
    if scen.false_spots:
        raise ConfigError(f"scenario '{scen.name}': false_spots are rendered by the head emulator only "
                          f"(head.kind = 'emulator'), not by head.kind = '{h.kind}'")
    if h.kind == "firmware-host":
        from .fwhead import FirmwareHead

        fw = FirmwareHead(h.program or None, sim, truth, seed, cfg.sim, scen.mag_limit or cfg.sim.mag_limit,
                          link=None if h.link == "none" else h.link)
        fw.start()
        faults.firmware_head = fw
        truth.on_restart.append(fw.set_origin)
        wiring = f"firmware host program {fw.program} on a pty (relay {fw.path}, link {h.link})"
        return fw.open_link, wiring, [fw.stop]

    def open_serial():
        return SerialLink(h.url, baudrate=h.baudrate)

    return open_serial, f"serial link {h.url} at {h.baudrate} Bd", []


def scenario_environment(scen: hc.Scenario, seed: int, horizon_s: float | None = None):
    """The scenario's orbit environment for the emulated head's sky
    (:class:`gyrostar.mocks.environment.Environment`), or None when every hazard is off."""
    if not scen.hazards:
        return None
    from ..mocks.environment import Environment

    return Environment.from_scenario(scen, seed, horizon_s)


class FaultPlan:
    """The scenario's injected faults, applied to the devices at their times (from its own
    thread, :meth:`start`, or by the caller's :meth:`apply`)."""

    def __init__(self, scen: hc.Scenario):
        self.faults = list(scen.faults)
        self.eclipse = list(scen.eclipse)
        self.gyro_bus = None
        self.head_emulator = None
        self.firmware_head = None
        self.active: set = set()
        # per fault: a link-corruption's ByteFaults counters when it ended (writes, mangled, injected)
        self.byte_counts: list[dict] = [{} for _ in self.faults]
        self.in_eclipse = False
        self._head_t = -math.inf     # the head's faults are applied up to here (only forward)
        # the times a head fault or an eclipse starts or ends, sorted (head_events_due)
        edges = {x for f in self.faults if f.kind in HEAD_FAULTS for x in (f.at_s, f.end_s) if x < math.inf}
        self._head_edges = sorted(edges | {x for a, b in self.eclipse for x in (a, b)})

    def start(self, t0: float, clock) -> None:
        """Apply the faults from their own thread (device calls may block; the loop must not)."""
        if not (self.faults or self.eclipse):
            return
        self._stop = threading.Event()

        def run():
            from ..realtime import join_realtime

            join_realtime(2)       # it touches the devices' state the loop reads: no inversion
            while not self._stop.wait(0.005):
                self.apply(clock.now() - t0)

        self._thread = threading.Thread(target=run, name="fault-injector", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        if getattr(self, "_thread", None) is not None:
            self._stop.set()
            self._thread.join(timeout=5.0)

    def head_events_due(self, t: float) -> bool:
        """:meth:`apply_head` at ``t`` might switch a head fault or an eclipse on or off: a
        start or an end of one lies after the time applied last and at or before ``t``."""
        if t <= self._head_t:
            return False
        edges = self._head_edges
        i = bisect.bisect_right(edges, self._head_t)
        return i < len(edges) and edges[i] <= t

    def stalled(self, t: float) -> bool:
        return any(f.kind == "gyro-fifo-overrun" and f.at_s <= t < f.at_s + f.seconds for f in self.faults)

    def eclipsed(self, t: float) -> bool:
        return any(a <= t < b for a, b in self.eclipse)

    def apply(self, t: float) -> None:
        self._apply(t, head=False)
        self.apply_head(t)

    def apply_head(self, t: float) -> None:
        """The head's faults and eclipses due by ``t``: a head job that ran ahead of the loop
        (fast mode) has applied them up to its own time already, and they never go back."""
        if t <= self._head_t:
            return
        self._head_t = t
        ecl = self.eclipsed(t)
        if ecl != self.in_eclipse:
            self.in_eclipse = ecl
            self._set_eclipse(ecl)
        self._apply(t, head=True)

    def _apply(self, t: float, head: bool) -> None:
        for i, f in enumerate(self.faults):
            if (f.kind in HEAD_FAULTS) != head:
                continue
            on = f.at_s <= t < f.end_s
            if on and i not in self.active:
                self.active.add(i)
                self._set(i, True)
            elif not on and i in self.active:
                self.active.discard(i)
                self._set(i, False)

    def close(self) -> None:
        """Switch off every fault still on (a clock step stays where it jumped)."""
        for i in sorted(self.active):
            if self.faults[i].kind != "head-clock-step":
                self._set(i, False)
        self.active.clear()

    def _set(self, i: int, on: bool) -> None:
        f = self.faults[i]
        log.info("fault %s %s", f.kind, "on" if on else "off")
        if f.kind == "gyro-nack" and self.gyro_bus is not None:
            if on:
                self.gyro_bus.nack_next(10**9)
            else:
                self.gyro_bus.nack_next(0)
        elif f.kind == "head-disconnect":
            dev = self.head_emulator or self.firmware_head
            if dev is not None:
                if on:
                    dev.disconnect()
                else:
                    dev.start()
        elif f.kind == "link-corruption":
            dev = self.head_emulator or self.firmware_head
            if dev is not None:
                if not on:
                    self.byte_counts[i] = dev.byte_fault_counts() or {}
                dev.set_byte_faults(f.byte_faults(seed=1000 + i) if on else None)
        elif f.kind == "head-clock-step" and on and self.head_emulator is not None:
            self.head_emulator.step_clock(f.step_s)

    def _set_eclipse(self, on: bool) -> None:
        """No starlight reaches the sensor (stars' signal 0; background and noise stay)."""
        log.info("eclipse %s", "begins" if on else "ends")
        dev = self.head_emulator or self.firmware_head
        if dev is not None:
            dev.eclipse(on)


def replay_loop(meta: dict, records, sinks):
    """The loop of a logged run rebuilt on replay taps; returns (loop, run_all)."""
    from .. import config as gconfig
    from ..camera import camera_preset

    cfg = gconfig.from_dict(meta["config"], hc.FlatsatConfig, source="log META")
    scen = gconfig.from_dict(meta["scenario"], hc.Scenario, source="log META")
    calib = load_calibration(cfg, meta.get("calibration") or {})
    camera = calib.camera(camera_preset(scen.preset or cfg.sim.preset) if emulated_head(cfg) else None,
                          real_head=not emulated_head(cfg))
    clock = taps.ReplayClock([float(np.frombuffer(r.payload, "<f8")[0]) for r in records
                              if r.kind == lf.CLOCK and r.channel == 0])
    lat = [float(np.frombuffer(r.payload, "<f8")[0]) for r in records
           if r.kind == lf.CLOCK and r.channel == lf.CH_LATENCY]
    lat_clock = taps.ReplayClock(lat) if lat else None
    regs = taps.ReplayRegisters([r for r in records if r.kind == lf.BUS and r.channel == lf.CH_GYRO])
    link = taps.ReplayLink([r for r in records if r.channel == lf.CH_HEAD and r.kind in (lf.TX, lf.RX, taps.WAITING)])
    e_per_dn = None
    if cfg.simulated:
        from ..mocks.sim_preset import load_preset

        e_per_dn = load_preset(scen.preset or cfg.sim.preset).detector.gain_e_per_adu
    head_clock = taps.ReplayClock([float(np.frombuffer(r.payload, "<f8")[0]) for r in records
                                   if r.kind == lf.CLOCK and r.channel == CH_HEAD_CLOCK])
    from collections import deque

    polls = deque(r.payload[0] for r in records if r.kind == POLL and r.channel == CH_POLL)
    reconnects = deque(r.payload[0] for r in records if r.kind == POLL and r.channel == CH_RECONNECT)
    irq_t = [float(np.frombuffer(r.payload, "<f8")[0]) for r in records if r.kind == lf.CLOCK and r.channel == CH_IRQ]
    irq = taps.ReplayClock(irq_t) if irq_t else None
    gyro = calib.gyro(make_gyro(cfg, regs, clock))
    head = make_head(cfg, link, clock, reconnect=None, head_clock=head_clock, replay_polls=polls,
                     replay_reconnects=reconnects, fast=bool(meta.get("fast")), replay_records=records)
    head = with_hot_pixels(head, calib, camera, {})
    # the σ the run used (its META says it; older logs: the rule of today)
    sigma = meta["camera_sigma_px"] if "camera_sigma_px" in meta else camera_sigma(cfg, scen, calib)
    loop = make_loop(cfg, clock, gyro, head, camera, sinks, lat_clock, e_per_dn, irq, scen,
                     sigma, gyro_scale_calibrated(calib), camera_bias(calib))

    def run_all():
        steps = 0
        try:
            loop.start()
            while True:
                loop.step()
                steps += 1
        except taps.ReplayExhausted as exc:
            return steps, f"end of log ({exc})"
        except taps.ReplayDivergence as exc:   # a corrupt stretch took records the loop needed, or a bug
            return steps, f"diverged from the log: {exc}"
        finally:
            loop.close()
            head.close()

    return loop, run_all
