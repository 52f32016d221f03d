"""The flatsat and scenario config reference (``docs/CONFIG.md``), generated from the schema.

Every table and key of :class:`gyrostar.hil.config.FlatsatConfig` and
:class:`gyrostar.hil.config.Scenario`, with its type, default and the comment written next to
the field in ``hil/config.py``. ``python -m gyrostar.hil.config_doc docs/CONFIG.md``
(``make config-doc``); a test fails when the file is stale.
"""

from __future__ import annotations

import dataclasses
import inspect
import io
import sys
import tokenize
import typing

from . import config as hc

HEADER = """# Configuration reference

Generated from the schema in `hil/config.py` by `make config-doc` (do not edit by hand).
TOML is validated against these dataclasses: an unknown key, a wrong type or a value out of
range is exit 2 naming the key and the file. Units are in the key names. A key a flatsat
file leaves out takes the default below, which is the built-in simulated flatsat's value: a
file of a few keys is the built-in flatsat with those keys changed.

"""


MEANING = {
    "name": "shown in the run summary and the log",
    "calibration": "calibration TOML from gyrostar calibrate (camera, gyro, alignment, dark), a relative path "
                   "taken from this config file's folder; required with a real head; --calibration (relative to "
                   "the current folder) overrides it",
    "head.kind": "emulator: Python head emulator; firmware-host: the C host build on a pty; serial: a real head",
    "min_track_fraction": "HIL acceptance: least fraction of the run in TRACK",
    "must_reacquire": "HIL acceptance: a full-frame re-acquisition must happen",
    "head.baudrate": "UART line rate, Bd (ignored by USB-CDC)",
    "head.pixel_format": "window pixels on the link: packed10 (10-bit packed) or u16",
    "head.retries": "retries after a timeout or a corrupt reply",
    "head.exposure_ms": "exposure time, ms",
    "head.gain": "sensor gain setting",
    "head.link": "line-rate model of the simulated link (uart-921k, uart-3m, usb-fs, usb-hs)",
    "gyro.kind": "emulator: BMI088 register model; i2c: /dev/i2c-N; spi: /dev/spidevB.D",
    "gyro.emulator_bus": "the bus the emulated gyro sits on: i2c (400 kHz) or spi (gyro.spi_hz); each transfer "
                         "takes its wire time, on the simulated clock in fast mode and asleep in real time",
    "gyro.model": "gyro part",
    "gyro.i2c_bus": "N of /dev/i2c-N",
    "gyro.i2c_address": "7-bit address (BMI088 gyro: 0x68 SDO low, 0x69 high)",
    "gyro.spi_bus": "B of /dev/spidevB.D",
    "gyro.spi_device": "D of /dev/spidevB.D",
    "gyro.spi_hz": "SPI clock, Hz",
    "gyro.range_dps": "full scale, °/s",
    "gyro.odr_hz": "output data rate, Hz",
    "gyro.fifo_watermark": ("FIFO frames per watermark interrupt: the loop steps at most this many gyro periods "
                            "apart (and at once when a frame is measured)"),
    "sim.preset": "simulator camera/optics/detector preset",
    "sim.catalog": "star catalog of the simulated sky",
    "sim.mag_limit": "faintest star rendered (V)",
    "loop.frame_hz": "image rate, Hz",
    "outputs.record": "write flatsat.gslog in the run folder",
    "outputs.udp_port": "UDP port of the raw output records",
    "outputs.udp_host": "destination of the raw output records (another host needs allow_remote)",
    "outputs.tm_host": "destination of the space packets (another host needs allow_remote)",
    "outputs.tm_port": "UDP port of the space packets",
    "outputs.tm_apid": "APID of the attitude packets",
    "outputs.tm_frame_apid": "APID of the mid-exposure packets (one per image update)",
    "realtime.cpus": "CPU affinity of the loop thread with --realtime ([] = any)",
    "description": "one line shown by gyrostar run",
    "duration_s": "default run length, s (--duration overrides)",
    "ra_deg": "start boresight right ascension, deg",
    "dec_deg": "start boresight declination, deg",
    "roll_deg": "start roll about the boresight, deg",
    "segments": "body-rate profile: list of segments (below)",
    "faults": "injected faults (below; emulated devices only)",
    "segments[].seconds": "segment length, s",
    "segments[].rate_dps": "body rate at the segment start, °/s (body axes)",
    "segments[].rate_end_dps": "body rate at its end (linear ramp); absent: constant",
    "faults[].kind": "what fails",
    "faults[].at_s": "start, s of scenario time",
    "faults[].seconds": "how long",
}


def _comments(cls) -> dict[str, str]:
    """field name → its ``#`` comment: on its line (with continuation lines aligned under it),
    else the comment lines just above it."""
    src = inspect.getsource(cls)
    toks = list(tokenize.generate_tokens(io.StringIO(src).readline))
    line_field: dict[int, str] = {}
    for i, tok in enumerate(toks):
        if (tok.type == tokenize.NAME and i + 1 < len(toks) and toks[i + 1].string == ":"
                and tok.start[1] == 4):
            line_field[tok.start[0]] = tok.string
    comments = {tok.start[0]: (tok.start[1], tok.string.lstrip("#").strip())
                for tok in toks if tok.type == tokenize.COMMENT}
    out: dict[str, str] = {}
    last = None
    above: list[str] = []
    for line in sorted(set(line_field) | set(comments)):
        col, text = comments.get(line, (None, None))
        if line in line_field:
            name = line_field[line]
            out[name] = text if text is not None else " ".join(above)
            last = name if text is not None else None
            above = []
        elif col is not None and col > 20 and last is not None:     # continuation aligned under it
            out[last] = f"{out[last]} {text}"
        elif col is not None:
            above.append(text)
            last = None
    return {k: v for k, v in out.items() if v}


def _type_name(tp) -> str:
    if typing.get_origin(tp) is typing.Literal:
        return " \\| ".join(repr(a).replace("'", '"') for a in typing.get_args(tp))
    s = getattr(tp, "__name__", None) or str(tp)
    return str(s).replace("typing.", "").replace(" | ", " \\| ")     # a union's bar is not a column


def _default(f, key: str = "") -> str:
    if f.default is not dataclasses.MISSING:
        v = f.default
    elif f.default_factory is not dataclasses.MISSING:
        v = f.default_factory()
    else:
        return "(required)"
    if dataclasses.is_dataclass(v):
        return "table"
    if isinstance(v, str):
        return f'"{v}"'
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int) and ("address" in key or "apid" in key):
        return f"0x{v:02X}"
    return repr(v)


def _table(cls, prefix: str, lines: list[str], nested: list) -> None:
    hints = typing.get_type_hints(cls)
    notes = _comments(cls)
    lines += ["| key | type | default | meaning |", "|-----|------|---------|---------|"]
    for f in dataclasses.fields(cls):
        tp = hints[f.name]
        if dataclasses.is_dataclass(tp):
            nested.append((tp, f"{prefix}{f.name}"))
            continue
        key = f"{prefix}{f.name}"
        meaning = notes.get(f.name) or MEANING.get(key, "")
        lines.append(f"| `{key}` | {_type_name(tp)} | `{_default(f, key)}` | {meaning} |")
    lines.append("")


def _doc(cls) -> str:
    d = (inspect.getdoc(cls) or "").split("\n\n")[0]
    return "" if d.startswith(cls.__name__ + "(") else d


def _section(cls, title: str, lines: list[str]) -> None:
    lines += [f"## {title}", ""] + ([_doc(cls), ""] if _doc(cls) else [])
    nested: list = []
    _table(cls, "", lines, nested)
    for sub, name in nested:
        lines += [f"### `[{name}]`", ""] + ([_doc(sub), ""] if _doc(sub) else [])
        _table(sub, f"{name}.", lines, [])


def render() -> str:
    lines = [HEADER]
    _section(hc.FlatsatConfig, "Flatsat config (`--config FILE`, built-in `hil/flatsat.toml`)", lines)
    _section(hc.Scenario, "Scenario (`--scenario NAME|FILE`, built-in `hil/scenarios/*.toml`)", lines)
    lines += ["### Scenario tables of lists", ""]
    for cls, name in ((hc.Segment, "segments"), (hc.Fault, "faults")):
        lines += [f"`{name}` entries: {_doc(cls)}", ""]
        _table(cls, f"{name}[].", lines, [])
    return "\n".join(lines).rstrip() + "\n"


def main(argv=None) -> int:
    from ..cli.output import write_or_print

    return write_or_print(render(), sys.argv[1:] if argv is None else argv)


if __name__ == "__main__":
    sys.exit(main())
