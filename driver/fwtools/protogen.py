"""Generate the C header and the Python constants from the ONE protocol definition.

Source: ``firmware/proto/protocol.toml``. Outputs (checked in, verified by a test):
``firmware/core/gs_proto_defs.h`` and ``driver/protocol/defs.py``.
``python -m gyrostar.fwtools.protogen --write`` regenerates them; without ``--write``
it exits 1 when a checked-in file is stale.
"""

from __future__ import annotations

import argparse
import sys
import textwrap
import tomllib
from pathlib import Path

from ..errors import ConfigError

SPEC_REL = Path("firmware/proto/protocol.toml")
C_HEADER_REL = Path("firmware/core/gs_proto_defs.h")
PY_DEFS_REL = Path("driver/protocol/defs.py")

TYPES = {"u8": ("B", 1, "uint8_t"), "u16": ("H", 2, "uint16_t"), "u32": ("I", 4, "uint32_t"),
         "u64": ("Q", 8, "uint64_t"), "i16": ("h", 2, "int16_t")}


def repo_root() -> Path:
    """The checkout holding firmware/ and driver/ (this file is driver/fwtools/protogen.py)."""
    return Path(__file__).resolve().parents[2]


def load_spec(path: Path | None = None) -> dict:
    """Parse and sanity-check protocol.toml; raise ConfigError naming the fault."""
    path = path or repo_root() / SPEC_REL
    with open(path, "rb") as fh:
        spec = tomllib.load(fh)
    ids, codes = set(), set()
    by_name = {m["name"]: m for m in spec["message"]}
    for msg in spec["message"]:
        if msg["id"] in ids:
            raise ConfigError(f"{path}: message id {msg['id']:#x} used twice")
        ids.add(msg["id"])
        for side in ("request", "reply"):
            layout = msg.get(side)
            if isinstance(layout, str):
                if layout not in by_name:
                    raise ConfigError(f"{path}: {msg['name']}.{side} refers to unknown {layout}")
                continue
            for field in layout or []:
                if field[1] not in TYPES:
                    raise ConfigError(f"{path}: {msg['name']}.{field[0]} has unknown type {field[1]}")
    for err in spec["error"]:
        if err["code"] in codes or not 0 < err["code"] < 0x10000:
            raise ConfigError(f"{path}: error code {err['code']} repeated or out of range")
        codes.add(err["code"])
    return spec


def _layout(spec: dict, msg: dict, side: str) -> list | None:
    layout = msg.get(side)
    if isinstance(layout, str):
        layout = next(m for m in spec["message"] if m["name"] == layout)[side]
    return layout


def _offsets(layout: list) -> tuple[list[tuple[str, str, int]], int]:
    out, off = [], 0
    for name, typ in layout:
        out.append((name, typ, off))
        off += TYPES[typ][1]
    return out, off


def render_c(spec: dict) -> str:
    """The C header text."""
    p, lim = spec["protocol"], spec["limits"]
    lines = ["/* gs_proto_defs.h - GENERATED from firmware/proto/protocol.toml by",
             " * `python -m gyrostar.fwtools.protogen --write`. Do not edit. */",
             "#ifndef GS_PROTO_DEFS_H", "#define GS_PROTO_DEFS_H", "", "#include <stdint.h>", ""]
    for key in ("version", "header_size", "crc_size", "reply_flag", "max_payload", "ping_max"):
        lines.append(f"#define GS_PROTO_{key.upper()} {p[key]}u")
    lines.append(f"#define GS_PROTO_CRC_CHECK 0x{p['crc_check']:08X}u")
    for key, val in spec["sensor"].items():
        lines.append(f"#define GS_SENSOR_DEFAULT_{key.upper()} {val}u")
    for key, val in lim.items():
        lines.append(f"#define GS_LIM_{key.upper()} {val}u")
    for key, val in spec["pixel_format"].items():
        lines.append(f"#define GS_PIXFMT_{key} {val}u")
    for key, val in spec["plane"].items():
        lines.append(f"#define GS_PLANE_{key} {val}u")
    lines.append("")
    for msg in spec["message"]:
        lines.append(f"#define GS_MSG_{msg['name']} 0x{msg['id']:02X}u")
    lines.append("")
    for err in spec["error"]:
        lines.append(f"#define GS_ERR_{err['name']} {err['code']}u")
    lines.append(f"#define GS_ERR_COUNT {len(spec['error'])}u")
    lines.append("")
    for msg in spec["message"]:
        for side, tag in (("request", "REQ"), ("reply", "REP")):
            layout = _layout(spec, msg, side)
            if layout is None:
                continue
            fields, size = _offsets(layout)
            lines.append(f"#define GS_{msg['name']}_{tag}_SIZE {size}u")
            for name, _typ, off in fields:
                lines.append(f"#define GS_{msg['name']}_{tag}_{name.upper()} {off}u")
    lines += ["", "#endif /* GS_PROTO_DEFS_H */", ""]
    return "\n".join(lines)


def render_py(spec: dict) -> str:
    """The Python defs module text."""
    p = spec["protocol"]
    out = ['"""Protocol constants and payload layouts — GENERATED from firmware/proto/protocol.toml',
           'by ``python -m gyrostar.fwtools.protogen --write``. Do not edit."""', "",
           "from enum import IntEnum", ""]
    for key in ("version", "header_size", "crc_size", "reply_flag", "max_payload", "ping_max"):
        out.append(f"{key.upper()} = {p[key]}")
    out.append(f"CRC_CHECK = 0x{p['crc_check']:08X}")
    out.append(f"SENSOR_DEFAULT = {dict(spec['sensor'])!r}")
    out.append("LIMITS = {")
    for key, val in spec["limits"].items():
        out.append(f"    {key!r}: {val},")
    out.append("}")
    out += ["", "", "class PixelFormat(IntEnum):", '    """Pixel encodings on the wire."""', ""]
    out += [f"    {k} = {v}" for k, v in spec["pixel_format"].items()]
    out += ["", "", "class Plane(IntEnum):", '    """Image planes of the sensor."""', ""]
    out += [f"    {k} = {v}" for k, v in spec["plane"].items()]
    out += ["", "", "class MsgType(IntEnum):",
            '    """Request message types (a reply is type | REPLY_FLAG; ERROR is reply-only)."""', ""]
    out += [f"    {m['name']} = 0x{m['id']:02X}" for m in spec["message"]]
    out += ["", "", "class ErrorCode(IntEnum):", '    """Firmware rejection codes (ERROR reply `code`)."""', ""]
    out += [f"    {e['name']} = {e['code']}" for e in spec["error"]]
    out += ["", "", "ERROR_TEXT = {"]
    out += [f"    ErrorCode.{e['name']}: {e['text']!r}," for e in spec["error"]]
    out += ["}", "", "# (struct format without byte-order prefix, field names) of each payload's fixed part."]
    for side in ("request", "reply"):
        out.append(f"{side.upper()}_LAYOUT = {{")
        for msg in spec["message"]:
            layout = _layout(spec, msg, side)
            if layout is None:
                continue
            fmt = "".join(TYPES[t][0] for _, t in layout)
            names = tuple(n for n, _ in layout)
            out.append(f"    MsgType.{msg['name']}: ({fmt!r}, (")
            out += textwrap.wrap(" ".join(f"{n!r}," for n in names), 100,
                                 initial_indent=" " * 8, subsequent_indent=" " * 8)
            out.append("    )),")
        out.append("}")
    out.append("TAIL = {")
    for msg in spec["message"]:
        if "tail" in msg:
            out.append(f"    MsgType.{msg['name']}: {msg['tail']!r},")
    out += ["}", ""]
    return "\n".join(out)


def generated(spec: dict | None = None) -> dict[Path, str]:
    """Relative path -> expected text of every generated file."""
    spec = spec or load_spec()
    return {C_HEADER_REL: render_c(spec), PY_DEFS_REL: render_py(spec)}


def stale(root: Path | None = None) -> list[Path]:
    """Generated files whose checked-in text differs from what the spec generates."""
    root = root or repo_root()
    bad = []
    for rel, text in generated(load_spec(root / SPEC_REL)).items():
        path = root / rel
        if not path.exists() or path.read_text() != text:
            bad.append(rel)
    return bad


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--write", action="store_true", help="rewrite the generated files")
    args = ap.parse_args(argv)
    root = repo_root()
    if args.write:
        for rel, text in generated(load_spec(root / SPEC_REL)).items():
            (root / rel).write_text(text)
            print(f"wrote {rel}")
        return 0
    bad = stale(root)
    for rel in bad:
        print(f"stale: {rel}", file=sys.stderr)
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
