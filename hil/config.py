"""Flatsat and scenario configuration (TOML, validated by :mod:`gyrostar.config`).

A **flatsat config** says which devices the loop talks to and where outputs go::

    [head]    kind = "emulator" | "firmware-host" | "serial";  url, baudrate, program,
              link (preset: uart-921k | uart-3m | usb-fs | usb-hs), mode (stream | request), pixel_format
    [gyro]    kind = "emulator" | "i2c" | "spi";  model, i2c_bus, i2c_address, spi_bus, ...
    [sim]     preset, gyro_errors, catalog, mag_limit        (simulated devices only)
    [loop]    rates, window size, identification settings
    [outputs] record, udp, udp_host, udp_port, space_packets, tm_host, tm_port, tm_apid, tm_frame_apid, allow_remote
    [realtime] sched_fifo_priority, cpus
    calibration = "path/to/calibration.toml"                  (optional)

A **scenario** says what the sky and the platform do: the start boresight, a body-rate
profile as piecewise-linear segments, star-less stretches (eclipse) and injected faults.
The built-in files are ``hil/flatsat.toml`` and ``hil/scenarios/*.toml``.
"""

from __future__ import annotations

import math
import typing
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Literal

from .. import config as gconfig
from ..errors import ConfigError


@dataclass
class HeadConfig:
    kind: Literal["emulator", "firmware-host", "serial"] = "emulator"
    url: str = ""                      # serial: /dev/ttyACM0, socket://host:port, rfc2217://...
    baudrate: int = 921600
    program: str = ""                  # firmware-host: path (default firmware/build/host/gyrostar-head)
    timeout_s: float = 0.05            # per request
    retries: int = 2
    exposure_ms: float = 10.0
    gain: int = 1
    # the head link (gyrostar.transport.linkrate preset): simulated links are paced at its line
    # rate and the loop budgets its windows with it. A 100 Hz head moves 0.15-0.5 MB/s, within
    # USB full speed (0.9 MB/s), beyond a 921.6 kBd UART; USB high speed (the default) also
    # keeps the exposure -> output time under 9 ms. "none": unpaced (head tests only)
    link: Literal["uart-921k", "uart-3m", "usb-fs", "usb-hs", "none"] = "usb-hs"
    mode: Literal["stream", "request"] = "stream"   # streaming head, or CAPTURE request by request
    pixel_format: Literal["packed10", "u16"] = "packed10"
    # lost-in-space image: the spot windows the head finds itself (FIND_SPOTS: a few kB on any
    # link) or the whole frame (1.3 MB: 0.16 s on usb-hs, 1.5 s on usb-fs, 14 s on uart-921k; bring-up)
    acquire: Literal["spots", "full_frame"] = "spots"

    def validate(self):
        from ..transport.linkrate import PRESETS

        if self.kind == "serial" and not self.url:
            raise ValueError("head.kind = 'serial' needs head.url (e.g. /dev/ttyACM0)")
        if self.link not in PRESETS and self.link != "none":
            raise ValueError(f"head.link {self.link!r} is not a link preset ({', '.join(PRESETS)}, or none)")
        if self.acquire not in ("spots", "full_frame"):
            raise ValueError(f"head.acquire {self.acquire!r} is not 'spots' or 'full_frame'")
        if not 0 < self.exposure_ms <= 100:
            raise ValueError(f"head.exposure_ms {self.exposure_ms} outside (0, 100]")
        if self.baudrate <= 0 or self.timeout_s <= 0 or self.retries < 0:
            raise ValueError(f"head.baudrate ({self.baudrate}) and head.timeout_s ({self.timeout_s}) must be > 0, "
                             f"head.retries ({self.retries}) ≥ 0")


@dataclass
class GyroConfig:
    kind: Literal["emulator", "i2c", "spi"] = "emulator"
    model: Literal["bmi088", "l3gd20h"] = "bmi088"
    emulator_bus: Literal["i2c", "spi"] = "i2c"
    i2c_bus: int = 1
    i2c_address: int = 0x68
    spi_bus: int = 0
    spi_device: int = 0
    spi_hz: int = 5_000_000
    range_dps: int = 500
    odr_hz: int = 400
    fifo_watermark: int = 4

    def validate(self):
        """Every value the chosen part accepts, from its driver's own tables."""
        part = gyro_part(self.model)
        if self.odr_hz not in part.odrs_hz:
            raise ValueError(f"gyro.odr_hz = {self.odr_hz}: the {part.name} supports {list(part.odrs_hz)} Hz")
        if self.range_dps not in part.ranges_dps:
            raise ValueError(f"gyro.range_dps = {self.range_dps}: the {part.name} supports "
                             f"±{list(part.ranges_dps)} °/s")
        if not 1 <= self.fifo_watermark <= part.max_watermark:
            raise ValueError(f"gyro.fifo_watermark = {self.fifo_watermark}: the {part.name} FIFO takes "
                             f"1..{part.max_watermark} frames")
        if self.kind == "i2c" and self.i2c_address not in part.i2c_addresses:
            raise ValueError(f"gyro.i2c_address = 0x{self.i2c_address:02x}: the {part.name} answers at "
                             f"{', '.join(f'0x{a:02x}' for a in part.i2c_addresses)}")
        if not 0x03 <= self.i2c_address <= 0x77:
            raise ValueError(f"gyro.i2c_address 0x{self.i2c_address:x} outside 0x03..0x77")
        if self.spi_hz <= 0:
            raise ValueError(f"gyro.spi_hz = {self.spi_hz} must be > 0")


@dataclass(frozen=True)
class GyroPart:
    """The settings a gyro part accepts, as its driver declares them."""

    name: str
    odrs_hz: tuple[int, ...]
    ranges_dps: tuple[int, ...]
    max_watermark: int
    i2c_addresses: tuple[int, ...]


def gyro_part(model: str) -> GyroPart:
    """The legal ODRs, ranges, FIFO watermarks and I2C addresses of ``model``, read from the
    driver module's tables (:mod:`gyrostar.gyro.bmi088`, :mod:`gyrostar.gyro.l3gd20h`)."""
    if model == "bmi088":
        from ..gyro import bmi088 as m

        return GyroPart("BMI088", tuple(sorted({odr for odr, _ in m.BANDWIDTHS.values()})),
                        tuple(sorted(m.RANGES_DPS)), m.FIFO_CAPACITY - 1, tuple(m.I2C_ADDRESSES))
    if model == "l3gd20h":
        from ..gyro import l3gd20h as m

        return GyroPart("L3GD20H", tuple(sorted(m.ODR_BITS)), tuple(sorted(m.FULL_SCALE)), m.FIFO_LEVELS - 1,
                        tuple(m.I2C_ADDRESSES))
    raise ValueError(f"gyro.model {model!r} has no driver")


@dataclass
class SimConfig:
    preset: Literal["xing2012", "qian2015"] = "xing2012"
    # a gyro error parameter set of gyrostar.mocks; the built-in flatsat's: paper 000's
    # calibrated BMI088-class gyro (the datasheet part, uncalibrated: "bmi088")
    gyro_errors: str = "xing2012"
    catalog: Literal["hip2", "gaia"] = "hip2"
    mag_limit: float = 8.0             # fainter than the camera detects (~V 7): their light reaches windows and blends


@dataclass
class LoopConfig:
    frame_hz: float = 100.0
    window_k: int = 6                  # k×k squares on the predicted trajectory (paper 000); +4 px for long streaks
    max_stars: int = 12                # stars tracked at once (≤ gyrostar.loop.record.MAX_STARS)
    min_stars: int = 2                 # fewer valid stars than this → COAST
    coast_timeout_s: float = 5.0       # COAST longer than this → ACQUIRE (full frame)
    acquire_every_s: float = 0.5       # full-frame attempt period while ACQUIRE
    mag_limit: float = 6.5             # stars predicted into the field brighter than this are tracked
    camera_sigma_px: float = 0.0       # camera-model uncertainty per centroid, px: the loop uses the largest of
                                       # this, the scenario's and a [camera] calibration's residual_rms_px (0
                                       # without a table: the model is exact, e.g. the simulator's preset; a
                                       # table with residual_rms_px = 0 needs this > 0)
    confirm_images: int = 20           # ACQUIRE: images that may fail to confirm an identification
    wrong_id_rejects: int = 5          # filter-gate rejections in a row that drop a star
    neighbour_sep_px: float = 12.0     # skip a catalog star closer than this (px, per axis) to a tracked one
    max_track_rate_dps: float = 20.0   # above this body rate (deg/s) images are not measured: the loop coasts
    reconnect_every_s: float = 0.25    # s between reconnection attempts while the head is away
    head_timeouts_lost: int = 3        # head jobs in a row without an answer that mean the link is lost
    stream_few_frames: int = 3         # streaming, tracking: images in a row with too few stars before COAST (frames)
    stream_gap_frames: int = 3         # streaming, link up: frame periods with no frame before each further one
                                       # counts as a starless image (frames)
    # gyro angle random walk N (IEEE, deg/sqrt(s)) for the filter's process noise; a simulated
    # flatsat uses its gyro model's (one-sided noise density / sqrt(2)); 0.0099 = BMI088 class
    gyro_arw_deg_rts: float = 0.0099
    # group delay of the gyro's low-pass filter (ms) for the loop to compensate (0: off). The
    # xing2012/bmi088 models' is 4.78 ms, but carrying each output over it with the latest
    # (noisy) rate sample costs more than the delay (fast demo: 4.44 -> 4.83 arcsec): off
    gyro_delay_ms: float = 0.0
    # cut-off of the gyro's 2nd-order low-pass (Hz; 0: none): it takes the rate noise above
    # it out of short windows (BMI088 at 400 Hz ODR: 47 Hz); the simulated flatsat uses its model's
    gyro_lowpass_hz: float = 47.0
    # rate-proportional gyro error left after calibration (scale factor and misalignment, 1σ,
    # ppm of the rate): the filter's attitude covariance grows with it at speed, linearly from
    # the last star fix. BMI088 uncalibrated: ~4700 (sensitivity ±1 %, cross-axis ±1 %); after
    # `gyrostar calibrate gyro-scale`: ~200. The simulated flatsat uses its gyro model's unless
    # the run's calibration has a [gyro_scale] table
    gyro_rate_error_ppm: float = 200.0
    # the gyro offset the filter starts from (1σ, deg/s): the BMI088's zero-rate offset is
    # ±1 deg/s raw, ~0.01 after `gyrostar calibrate gyro-static`. The simulated flatsat uses its
    # gyro model's (3σ of the per-part draw, or the fixed offset)
    gyro_bias_prior_dps: float = 1.15

    def validate(self):
        from ..loop.record import MAX_STARS

        if not 0 <= self.camera_sigma_px <= 20:
            raise ValueError(f"loop.camera_sigma_px {self.camera_sigma_px} outside [0, 20]")
        for key in ("confirm_images", "wrong_id_rejects", "head_timeouts_lost", "stream_few_frames",
                    "stream_gap_frames"):
            if getattr(self, key) < 1:
                raise ValueError(f"loop.{key} must be at least 1")
        if not 0.0 <= self.gyro_lowpass_hz < 10000.0:
            raise ValueError("loop.gyro_lowpass_hz must be in [0, 10000)")
        if not 0.0 <= self.gyro_delay_ms < 100.0:
            raise ValueError("loop.gyro_delay_ms must be in [0, 100)")
        if not 0.0 < self.max_track_rate_dps <= 200.0:
            raise ValueError("loop.max_track_rate_dps must be in (0, 200]")
        if not 0.0 < self.gyro_bias_prior_dps <= 10.0:
            raise ValueError("loop.gyro_bias_prior_dps must be in (0, 10]")
        if not 0.0 <= self.gyro_rate_error_ppm <= 1e5:
            raise ValueError("loop.gyro_rate_error_ppm must be in [0, 100000]")
        for key in ("neighbour_sep_px", "reconnect_every_s", "gyro_arw_deg_rts"):
            if not getattr(self, key) > 0:
                raise ValueError(f"loop.{key} must be positive")
        if self.frame_hz <= 0:
            raise ValueError(f"loop.frame_hz = {self.frame_hz} must be > 0 (images per second)")
        for key in ("coast_timeout_s", "acquire_every_s"):
            if getattr(self, key) <= 0:
                raise ValueError(f"loop.{key} = {getattr(self, key)} must be > 0")
        if not 1 <= self.min_stars <= self.max_stars:
            raise ValueError(f"loop.min_stars = {self.min_stars} outside 1..loop.max_stars ({self.max_stars})")

        if not 1 <= self.max_stars <= MAX_STARS:
            raise ValueError(f"loop.max_stars {self.max_stars} outside 1..{MAX_STARS}")
        if self.window_k < 3 or self.window_k > 32:
            raise ValueError(f"loop.window_k {self.window_k} outside 3..32")


@dataclass
class OutputsConfig:
    record: bool = True
    udp: bool = False                  # raw output records (GYS1 datagrams, gyrostar.loop.sinks)
    udp_host: str = "127.0.0.1"
    udp_port: int = 47800
    space_packets: bool = False        # CCSDS Space Packets, one per output (gyrostar.telemetry.packets)
    tm_host: str = "127.0.0.1"
    tm_port: int = 47801
    tm_apid: int = 0x0A1
    tm_frame_apid: int = 0x0A2         # the mid-exposure packets, one per image update
    allow_remote: bool = False         # let udp_host / tm_host be another machine

    def validate(self):
        for name in ("udp_port", "tm_port"):
            if not 0 < getattr(self, name) < 65536:
                raise ValueError(f"outputs.{name} {getattr(self, name)} outside 1..65535")
        for name in ("tm_apid", "tm_frame_apid"):
            if not 0 <= getattr(self, name) <= 0x7FE:
                raise ValueError(f"outputs.{name} 0x{getattr(self, name):x} outside 0..0x7FE (0x7FF is the idle APID)")
        if self.tm_frame_apid == self.tm_apid:
            raise ValueError(f"outputs.tm_frame_apid 0x{self.tm_frame_apid:x} is tm_apid's: the frame packets need "
                             "their own APID")


@dataclass
class RealtimeConfig:
    # the loop thread's SCHED_FIFO priority (0 = do not ask; not granted: a note, SCHED_OTHER)
    sched_fifo_priority: int = 50
    cpus: list[int] = field(default_factory=list)


@dataclass
class FlatsatConfig:
    name: str = "simulated flatsat"
    head: HeadConfig = field(default_factory=HeadConfig)
    gyro: GyroConfig = field(default_factory=GyroConfig)
    sim: SimConfig = field(default_factory=SimConfig)
    loop: LoopConfig = field(default_factory=LoopConfig)
    outputs: OutputsConfig = field(default_factory=OutputsConfig)
    realtime: RealtimeConfig = field(default_factory=RealtimeConfig)
    calibration: str = ""

    def validate(self):
        if self.loop.frame_hz > self.gyro.odr_hz:
            raise ValueError(f"loop.frame_hz = {self.loop.frame_hz:g} exceeds gyro.odr_hz = {self.gyro.odr_hz} "
                             "(the loop steps once per gyro period)")
        period_ms = 1000.0 / self.loop.frame_hz
        if self.head.exposure_ms > period_ms + 1e-9:
            raise ValueError(f"head.exposure_ms = {self.head.exposure_ms:g} is longer than the frame period of "
                             f"loop.frame_hz = {self.loop.frame_hz:g} ({period_ms:g} ms)")

    @property
    def simulated(self) -> bool:
        """True when both devices are simulated (emulator or firmware host on a pty)."""
        return self.head.kind in ("emulator", "firmware-host") and self.gyro.kind == "emulator"


# bounds of a scenario, checked when it is read (a TOML file or mc:SEED@DURATION), before
# anything is drawn, built or run: a day of flatsat time, the gyros' widest range (BMI088 and
# L3GD20H: ±2000 °/s), and as many segments, faults, eclipses or glints as a day could use
MAX_SCENARIO_S = 86400.0
MAX_RATE_DPS = 2000.0
MAX_SCENARIO_ITEMS = 10000


@dataclass
class Segment:
    """Body rate ramps linearly from ``rate_dps`` to ``rate_end_dps`` over ``seconds``."""

    seconds: float
    rate_dps: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rate_end_dps: tuple[float, float, float] | None = None

    def validate(self):
        if not 0 < self.seconds <= MAX_SCENARIO_S:
            raise ValueError(f"segment length {self.seconds} s must be in (0, {MAX_SCENARIO_S:g}] s")
        for key, rate in (("rate_dps", self.rate_dps), ("rate_end_dps", self.rate_end_dps or (0.0, 0.0, 0.0))):
            if not all(math.isfinite(v) and abs(v) <= MAX_RATE_DPS for v in rate):
                raise ValueError(f"segment {key} = {list(rate)} must be finite and within ±{MAX_RATE_DPS:g} °/s "
                                 "per axis (the gyro's widest range)")


@dataclass
class Fault:
    """A fault injected at ``at_s`` for ``seconds`` (a clock step: at ``at_s``, for good): see
    the scenarios paragraph in FLATSAT.md."""

    kind: Literal["head-disconnect", "link-corruption", "gyro-fifo-overrun", "gyro-nack", "head-clock-step"]
    at_s: float
    seconds: float = 0.0
    rate: float = 0.01                 # link-corruption: fraction of bytes corrupted
    drop_rate: float = 0.0             # link-corruption: fraction of bytes dropped
    garbage_rate: float = 0.0          # link-corruption: fraction of replies preceded by 8–64 random bytes
    step_s: float = 0.0                # head-clock-step: s the head MCU's clock jumps by, the link open
                                       # (+ ahead, as across a host suspend of the flight computer; − back)

    def byte_faults(self, seed: int) -> dict:
        """A link-corruption's :class:`~gyrostar.mocks.faults.ByteFaults` keyword arguments."""
        return {"corrupt_p": self.rate, "drop_p": self.drop_rate, "garbage_p": self.garbage_rate, "seed": seed}

    @property
    def end_s(self) -> float:
        """Scenario time the fault ends (s): a clock step never ends (the clock stays where it jumped)."""
        return math.inf if self.kind == "head-clock-step" else self.at_s + self.seconds

    def validate(self):
        kinds = typing.get_args(typing.get_type_hints(Fault)["kind"])
        if self.kind not in kinds:
            raise ValueError(f"kind = {self.kind!r} must be one of {', '.join(kinds)}")
        if self.at_s < 0:
            raise ValueError(f"at_s = {self.at_s} must be ≥ 0 (s from the start of the run)")
        if not self.at_s <= MAX_SCENARIO_S:
            raise ValueError(f"at_s = {self.at_s} must be at most {MAX_SCENARIO_S:g} s (a day)")
        if not 0 <= self.seconds <= MAX_SCENARIO_S:
            raise ValueError(f"seconds = {self.seconds} must be in [0, {MAX_SCENARIO_S:g}]")
        if self.kind == "head-clock-step":
            if not (math.isfinite(self.step_s) and abs(self.step_s) >= 0.001):
                raise ValueError(f"step_s = {self.step_s} must be a finite jump of at least 0.001 s either way "
                                 "(head-clock-step: what the head MCU's clock jumps by)")
        elif not self.seconds > 0:
            raise ValueError(f"seconds = {self.seconds} must be > 0 (a fault of 0 s never fires)")
        for name in ("rate", "drop_rate", "garbage_rate"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise ValueError(f"{name} = {getattr(self, name)} must be in [0, 1] (link-corruption: a fraction)")
        if self.kind == "link-corruption" and not (self.rate or self.drop_rate or self.garbage_rate):
            raise ValueError("a link-corruption with rate, drop_rate and garbage_rate all 0 injects nothing")


@dataclass
class TrueDevices:
    """How the simulated devices differ from their nominal models: what calibration must find.

    The head emulator renders through the true camera, the emulated gyro senses in its own
    frame and stamps its samples off by the time offset; the loop still starts from the
    nominal camera and an identity mounting unless a calibration file says otherwise."""

    focal_scale: float = 1.0                                  # true focal length / nominal
    principal_offset_px: tuple[float, float] = (0.0, 0.0)     # true − nominal principal point (column, row)
    k1: float = 0.0                                           # Brown–Conrady k1 of the true optics
    gyro_rotation_deg: tuple[float, float, float] = (0.0, 0.0, 0.0)   # rotation vector gyro → camera, deg
    gyro_time_offset_ms: float = 0.0     # camera time − gyro time stamp (the calibration's time_offset_s), ms

    def validate(self):
        if not 0.9 < self.focal_scale < 1.1:
            raise ValueError(f"truth.focal_scale {self.focal_scale} outside (0.9, 1.1)")
        if abs(self.gyro_time_offset_ms) > 50:
            raise ValueError(f"truth.gyro_time_offset_ms {self.gyro_time_offset_ms} outside ±50 ms")

    @property
    def nominal(self) -> bool:
        return self == TrueDevices()


def _in_range(table: str, obj, lo: float, hi: float, *keys: str) -> None:
    """ValueError naming ``table.key`` for the first of ``keys`` of ``obj`` outside [lo, hi]."""
    for key in keys:
        v = getattr(obj, key)
        if not (math.isfinite(v) and lo <= v <= hi):
            raise ValueError(f"{table}.{key} = {v} outside [{lo:g}, {hi:g}]")


@dataclass
class OrbitConfig:
    """The spacecraft's circular orbit and the run's epoch: the Sun, the Moon, the Earth's limb and
    the Earth's shadow follow from it (:mod:`gyrostar.mocks.orbit`). Off: no Sun, Moon or Earth."""

    enabled: bool = False              # the Sun, the Moon and the Earth around the spacecraft
    altitude_km: float = 500.0         # altitude of the circular orbit, km
    inclination_deg: float = 97.4      # sun-synchronous at 500 km
    ltan_h: float = 10.5               # local time of the ascending node, h: the node's right ascension is
                                       # the Sun's at the epoch + 15°/h · (ltan_h − 12)
    raan_deg: float | None = None      # right ascension of the ascending node, deg: replaces ltan_h when set
    phase_deg: float = 0.0             # argument of latitude at scenario time 0, deg (0: the ascending node)
    epoch_utc: str = "2026-03-20T12:00:00"   # UTC at scenario time 0 (ISO 8601)

    def validate(self):
        _in_range("orbit", self, 160.0, 2000.0, "altitude_km")
        _in_range("orbit", self, 0.0, 180.0, "inclination_deg")
        _in_range("orbit", self, 0.0, 24.0, "ltan_h")
        _in_range("orbit", self, -360.0, 360.0, "phase_deg", *(["raan_deg"] if self.raan_deg is not None else []))
        from datetime import datetime

        try:
            t = datetime.fromisoformat(self.epoch_utc)
        except ValueError:
            raise ValueError(f"orbit.epoch_utc = {self.epoch_utc!r} is not an ISO 8601 time "
                             "(e.g. 2026-03-20T12:00:00)") from None
        if not 1950 <= t.year <= 2100:
            raise ValueError(f"orbit.epoch_utc = {self.epoch_utc!r}: the built-in ephemeris covers 1950..2100")


@dataclass
class StrayLightConfig:
    """Background from the Sun, the sunlit Earth and the Moon outside the field, through the baffle's
    point-source transmittance (PST) curve (docs/SIMULATOR.md, "Stray light"); needs [orbit]."""

    enabled: bool = False              # background from the Sun, the Moon and the sunlit Earth
    exclusion_deg: float = 30.0        # the baffle's cut-off angle from the boresight: closer, the first lens
                                       # is lit and the sensor is blinded
    pst_edge: float = 1.0e-3           # PST of a source just outside the field (lit first lens)
    pst_exclusion: float = 1.0e-9      # PST just beyond the exclusion angle (vanes' double scatter)
    slope: float = 2.0                 # PST ∝ θ^-slope beyond the exclusion angle
    transition_deg: float = 0.5        # width of the drop at the baffle's cut-off (logistic scale), deg
    earth_albedo: float = 0.3          # Bond albedo of the sunlit Earth

    def validate(self):
        _in_range("stray_light", self, 5.0, 90.0, "exclusion_deg")
        if not 0.0 < self.pst_exclusion < self.pst_edge <= 1.0:
            raise ValueError("stray_light: need 0 < pst_exclusion < pst_edge <= 1")
        _in_range("stray_light", self, 0.0, 6.0, "slope")
        _in_range("stray_light", self, 0.05, 10.0, "transition_deg")
        _in_range("stray_light", self, 0.0, 1.0, "earth_albedo")


@dataclass
class MoonConfig:
    """The Moon rendered as a resolved disk (phase-lit, saturating) when it is in the field, and
    the stars behind it hidden; needs [orbit]."""

    enabled: bool = False              # the Moon's disk and its hidden stars


@dataclass
class RadiationConfig:
    """Particle hits per frame (Poisson; short tracks, a Landau-like charge) with a higher flux
    inside the South Atlantic Anomaly, and hot pixels that appear during the run."""

    enabled: bool = False              # particle hits and new hot pixels
    flux_cm2_s: float = 2.0            # particles per cm² per s outside the SAA (galactic cosmic rays, LEO)
    saa_flux_cm2_s: float = 300.0      # inside the SAA box (trapped protons through the head's shielding)
    saa_lat_deg: tuple[float, float] = (-50.0, 0.0)      # the SAA box: latitude range of the sub-satellite point
    saa_lon_deg: tuple[float, float] = (-90.0, 40.0)     # longitude range (east +), deg
    depth_um: float = 10.0             # charge-collection depth: a track at incidence θ runs depth·tan θ
    charge_e_per_um: float = 80.0      # most probable charge per µm of path in silicon (minimum ionising)
    landau_width: float = 0.15         # Landau (Moyal) width relative to the most probable charge
    hot_pixels_per_hour: float = 0.0   # new hot pixels per hour of run (displacement damage)
    hot_pixel_dark_e_s: float = 20000.0   # dark current of a new hot pixel, e-/s (median; log-normal 0.5 dex)

    def validate(self):
        _in_range("radiation", self, 0.0, 1e5, "flux_cm2_s", "saa_flux_cm2_s", "hot_pixels_per_hour",
                  "hot_pixel_dark_e_s")
        for key, lim in (("saa_lat_deg", 90.0), ("saa_lon_deg", 180.0)):
            a, b = getattr(self, key)
            if not -lim <= a < b <= lim:
                raise ValueError(f"radiation.{key} = [{a}, {b}] must satisfy -{lim:g} <= low < high <= {lim:g}")
        _in_range("radiation", self, 0.5, 100.0, "depth_um")
        _in_range("radiation", self, 1.0, 1e4, "charge_e_per_um")
        _in_range("radiation", self, 0.0, 1.0, "landau_width")


@dataclass
class ThermalConfig:
    """Sensor temperature over the run: dark current doubling every ``dark_doubling_c`` and the
    focal length drifting by ``focal_ppm_per_c`` from the preset's values at ``reference_c``."""

    enabled: bool = False              # dark current and focal length follow the temperature
    temperature_c: float = 20.0        # mean sensor temperature, °C
    swing_c: float = 0.0               # amplitude of a sinusoid over one orbit period, °C
    rate_c_per_s: float = 0.0          # steady drift, °C/s (e.g. a warm-up)
    reference_c: float = 20.0          # the temperature of the preset's dark current and focal length
    dark_doubling_c: float = 7.0       # dark current doubles every this many °C
    focal_ppm_per_c: float = 4.0       # focal-length change, ppm/°C (N-BK7 singlet: α − (dn/dT)/(n − 1))

    def validate(self):
        _in_range("thermal", self, -60.0, 100.0, "temperature_c", "reference_c")
        _in_range("thermal", self, 0.0, 60.0, "swing_c")
        _in_range("thermal", self, -1.0, 1.0, "rate_c_per_s")
        _in_range("thermal", self, 2.0, 20.0, "dark_doubling_c")
        _in_range("thermal", self, -200.0, 200.0, "focal_ppm_per_c")


@dataclass
class Scenario:
    name: str
    description: str = ""
    duration_s: float = 30.0
    ra_deg: float = 80.0
    dec_deg: float = 20.0
    roll_deg: float = 0.0
    segments: list[Segment] = field(default_factory=list)
    eclipse: list[tuple[float, float]] = field(default_factory=list)   # [start_s, end_s] with no stars
    faults: list[Fault] = field(default_factory=list)
    preset: str = ""                   # overrides sim.preset when set
    gyro_errors: str = ""              # overrides sim.gyro_errors when set
    mag_limit: float = 0.0             # overrides sim.mag_limit when > 0
    camera_sigma_px: float = 0.0       # camera-model σ, px: the loop uses the largest of this, loop.camera_sigma_px
                                       # and a [camera] calibration's residual_rms_px
    coast_timeout_s: float = 0.0       # overrides loop.coast_timeout_s when > 0 (s): fast slews, re-acquire after each
    acquire_every_s: float = 0.0       # overrides loop.acquire_every_s when > 0 (s): re-acquire soon after a fast slew
    max_stars: int = 0                 # overrides loop.max_stars when > 0: a calibration run takes every star it can
    truth: TrueDevices = field(default_factory=TrueDevices)   # simulated devices off their nominal models
    gyro_overrides: dict[str, float] = field(default_factory=dict)  # fields of the gyro error set replaced
    false_spots: list[tuple[float, float, float]] = field(default_factory=list)  # [col, row, vmag] glints
    # the orbit environment (every part off by default; docs/SIMULATOR.md, "Orbit environment")
    orbit: OrbitConfig = field(default_factory=OrbitConfig)
    stray_light: StrayLightConfig = field(default_factory=StrayLightConfig)
    moon: MoonConfig = field(default_factory=MoonConfig)
    radiation: RadiationConfig = field(default_factory=RadiationConfig)
    thermal: ThermalConfig = field(default_factory=ThermalConfig)
    # acceptance of the scenario in the HIL suite
    max_error_arcsec_1sigma: float = 0.0   # 0 = not checked
    max_error_over_floor: float = 0.0      # attitude error over the run's own floor at most this (0 = not checked)
    min_track_fraction: float = 0.0
    must_reacquire: bool = False
    max_samples_lost: int = 0          # gyro samples the run may lose (FIFO overflow), checked on every run
                                       # however long; -1 = not checked (a scenario that stalls the loop sets its own)

    def validate(self):
        if not 0 < self.duration_s <= MAX_SCENARIO_S:
            raise ValueError(f"duration_s = {self.duration_s} must be in (0, {MAX_SCENARIO_S:g}] s")
        for key in ("segments", "eclipse", "faults", "false_spots"):
            if len(getattr(self, key)) > MAX_SCENARIO_ITEMS:
                raise ValueError(f"{key} has {len(getattr(self, key))} entries: at most {MAX_SCENARIO_ITEMS}")
        if self.max_samples_lost < -1:
            raise ValueError(f"max_samples_lost = {self.max_samples_lost} must be ≥ 0 (-1: not checked)")
        if not 0.0 <= self.coast_timeout_s <= 60.0:
            raise ValueError(f"coast_timeout_s = {self.coast_timeout_s} must be in [0, 60] s (0: the config's)")
        if not 0.0 <= self.acquire_every_s <= 60.0:
            raise ValueError(f"acquire_every_s = {self.acquire_every_s} must be in [0, 60] s (0: the config's)")
        from ..loop.record import MAX_STARS

        if not 0 <= self.max_stars <= MAX_STARS:
            raise ValueError(f"max_stars = {self.max_stars} must be in [0, {MAX_STARS}] (0: the config's)")
        if not 0.0 <= self.min_track_fraction <= 1.0:
            raise ValueError(f"min_track_fraction = {self.min_track_fraction} must be in [0, 1]")
        if self.max_error_over_floor < 0:
            raise ValueError(f"max_error_over_floor = {self.max_error_over_floor} must be ≥ 0 (0: not checked)")
        if self.max_error_arcsec_1sigma < 0:
            raise ValueError(f"max_error_arcsec_1sigma = {self.max_error_arcsec_1sigma} must be ≥ 0 (0: not checked)")
        for a, b in self.eclipse:
            if not 0 <= a < b:
                raise ValueError(f"eclipse [{a}, {b}] must satisfy 0 <= start < end")
        for key in ("stray_light", "moon"):
            if getattr(self, key).enabled and not self.orbit.enabled:
                raise ValueError(f"[{key}] needs [orbit] enabled = true (the Sun, Moon and Earth come from the orbit)")

    @property
    def hazards(self) -> list[str]:
        """The orbit-environment parts switched on (``orbit``, ``stray_light``, ``moon``,
        ``radiation``, ``thermal``): empty for the flatsat's kind sky."""
        return [k for k in HAZARD_TABLES if getattr(self, k).enabled]


HAZARD_TABLES = ("orbit", "stray_light", "moon", "radiation", "thermal")


def default_config_path() -> Path:
    return Path(str(resources.files("gyrostar.hil") / "flatsat.toml"))


def load_flatsat(path: str | Path | None = None) -> FlatsatConfig:
    """The flatsat config at ``path`` (default: the built-in simulated flatsat). A relative
    ``calibration`` path is taken from the config file's folder, wherever the command runs."""
    path = Path(path or default_config_path())
    cfg = gconfig.load(path, FlatsatConfig)
    if cfg.calibration and not Path(cfg.calibration).expanduser().is_absolute():
        cfg.calibration = str(path.parent / Path(cfg.calibration).expanduser())
    return cfg


def scenario_names() -> list[str]:
    folder = resources.files("gyrostar.hil") / "scenarios"
    return sorted(p.name[:-5] for p in folder.iterdir() if p.name.endswith(".toml"))


def load_scenario(name_or_path: str | None) -> Scenario:
    """A built-in scenario by name (default ``demo``), a scenario TOML file by path, or a
    Monte Carlo case ``mc:SEED@DURATION`` (``gyrostar eval loop``; run it with ``--seed SEED``) or
    ``mco:SEED@DURATION`` (an orbit case, ``gyrostar eval loop --orbit``)."""
    name_or_path = name_or_path or "demo"
    if name_or_path.startswith(("mc:", "mco:")):
        from .montecarlo.cases import case_scenario, draw_case
        from .montecarlo.orbit_cases import draw_orbit_case, orbit_case_scenario

        prefix = name_or_path.split(":", 1)[0]
        try:
            seed_s, dur_s = name_or_path[len(prefix) + 1:].split("@")
            seed, dur = int(seed_s), float(dur_s)
            if not (math.isfinite(dur) and 0 < dur <= MAX_SCENARIO_S):     # before the case is drawn
                raise ValueError(f"DURATION must be a number of seconds in (0, {MAX_SCENARIO_S:g}], got {dur_s!r}")
            if prefix == "mco":
                return orbit_case_scenario(draw_orbit_case(seed, dur), dur)
            return case_scenario(draw_case(seed, dur), dur)
        except ValueError as exc:
            raise ConfigError(f"--scenario {name_or_path}: a Monte Carlo case is {prefix}:SEED@DURATION, "
                              f"e.g. {prefix}:100007@30 ({exc})") from None
    path = Path(name_or_path)
    if not path.suffix == ".toml":
        path = Path(str(resources.files("gyrostar.hil") / "scenarios" / f"{name_or_path}.toml"))
        if not path.exists():
            raise ConfigError(f"unknown scenario '{name_or_path}' (built-in: {', '.join(scenario_names())})")
    return gconfig.load(path, Scenario)
