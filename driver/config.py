"""TOML configuration with strict validation against dataclass schemas.

A schema is a (nested) dataclass. :func:`load` reads a TOML file with :mod:`tomllib` and
builds the dataclass, rejecting any unknown key or ill-typed value with a
:class:`~gyrostar.errors.ConfigError` that names the key, the file and the expected type.

Supported field types: ``bool``, ``int``, ``float`` (ints accepted), ``str``, ``Path``,
``Literal[...]``, ``X | None``, ``list[X]``, ``tuple[X, ...]``, ``tuple[X, Y, Z]``,
``dict[str, X]`` and nested dataclasses. Fields without defaults are required.
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
import types
import typing
from pathlib import Path
from typing import Any, Literal, TypeVar, get_args, get_origin

from .errors import ConfigError

T = TypeVar("T")


def load(path: str | Path, schema: type[T]) -> T:
    """Read ``path`` (TOML) and validate it into an instance of ``schema``."""
    path = Path(path)
    return loads(read_text(path), schema, source=str(path), what="config file")


def loads(text: str, schema: type[T], source: str = "<string>", what: str = "config") -> T:
    """Validate TOML text into ``schema`` (``source`` names it in errors)."""
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{what} {source} is not valid TOML: {exc}") from exc
    return from_dict(raw, schema, source=source)


def read_text(path: str | Path, what: str = "config file") -> str:
    """The text of ``path``; ``ConfigError`` naming it when missing, unreadable or not UTF-8."""
    return decode(read_bytes(path, what), path, what)


def read_bytes(path: str | Path, what: str = "config file") -> bytes:
    """The bytes of ``path``; ``ConfigError`` naming it when missing, unreadable, not a
    regular file (a folder, a FIFO, ``/dev/zero``) or larger than a TOML file can be
    (:func:`gyrostar.files.read_regular`)."""
    from .files import TOML_MAX_BYTES, read_regular

    return read_regular(path, what, TOML_MAX_BYTES)


def decode(data: bytes, path: str | Path, what: str = "config file") -> str:
    """``data`` as UTF-8 text; ``ConfigError`` naming ``path`` when it is not (a binary file)."""
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ConfigError(f"{what} {path} is not UTF-8 text TOML (byte {exc.start}: "
                          f"{data[exc.start:exc.start + 1]!r})") from None


def from_dict(raw: dict, schema: type[T], source: str = "<dict>", prefix: str = "") -> T:
    """Validate a plain mapping into ``schema``."""
    if not isinstance(raw, dict):
        raise ConfigError(f"{source}: '{prefix or '<root>'}' must be a table, got {_tname(raw)}")
    hints = typing.get_type_hints(schema)
    fields = {f.name: f for f in dataclasses.fields(schema)}
    unknown = sorted(set(raw) - set(fields))
    if unknown:
        key = _join(prefix, unknown[0])
        raise ConfigError(
            f"{source}: unknown key '{key}' (known keys here: {', '.join(sorted(fields)) or 'none'})"
        )
    kwargs = {}
    for name, field in fields.items():
        key = _join(prefix, name)
        if name in raw:
            kwargs[name] = _coerce(raw[name], hints[name], source, key)
        elif field.default is dataclasses.MISSING and field.default_factory is dataclasses.MISSING:
            raise ConfigError(f"{source}: missing required key '{key}' ({_describe(hints[name])})")
    obj = schema(**kwargs)
    check = getattr(obj, "validate", None)
    if callable(check):
        try:
            check()
        except ValueError as exc:
            text = str(exc)
            where = "" if not prefix or text.startswith(prefix + ".") else f"[{prefix}] "
            raise ConfigError(f"{source}: {where}{text}") from exc
    return obj


def to_dict(obj: Any) -> Any:
    """Inverse of :func:`from_dict` (Paths become strings, tuples lists)."""
    if dataclasses.is_dataclass(obj):
        return {f.name: to_dict(getattr(obj, f.name)) for f in dataclasses.fields(obj)
                if getattr(obj, f.name) is not None}
    if isinstance(obj, (list, tuple)):
        return [to_dict(v) for v in obj]
    if isinstance(obj, dict):
        return {k: to_dict(v) for k, v in obj.items()}
    if isinstance(obj, Path):
        return str(obj)
    return obj


def _coerce(value: Any, tp: Any, source: str, key: str) -> Any:
    origin = get_origin(tp)
    args = get_args(tp)
    if origin in (typing.Union, types.UnionType):
        if value is None and type(None) in args:
            return None
        errors = []
        for alt in args:
            if alt is type(None):
                continue
            try:
                return _coerce(value, alt, source, key)
            except ConfigError as exc:
                errors.append(exc)
        if len(errors) == 1:        # ``X | None``: what is wrong inside X (e.g. a nested table's key)
            raise errors[0]
        raise _bad(source, key, tp, value)
    if origin is Literal:
        if value in args and type(value) in {type(a) for a in args}:
            return value
        raise ConfigError(f"{source}: key '{key}' must be one of {list(args)}, got {value!r}")
    if origin in (list, tuple):
        if not isinstance(value, list):
            raise _bad(source, key, tp, value)
        if origin is tuple and args and args[-1] is not Ellipsis:
            if len(value) != len(args):
                raise ConfigError(f"{source}: key '{key}' must have {len(args)} items, got {len(value)}")
            return tuple(_coerce(v, a, source, f"{key}[{i}]") for i, (v, a) in enumerate(zip(value, args)))
        item = args[0] if args else Any
        out = [_coerce(v, item, source, f"{key}[{i}]") for i, v in enumerate(value)]
        return tuple(out) if origin is tuple else out
    if origin is dict:
        if not isinstance(value, dict):
            raise _bad(source, key, tp, value)
        vt = args[1] if len(args) == 2 else Any
        return {str(k): _coerce(v, vt, source, _join(key, str(k))) for k, v in value.items()}
    if dataclasses.is_dataclass(tp):
        return from_dict(value, tp, source, key)
    if tp is Any:
        return value
    if tp is bool:
        if isinstance(value, bool):
            return value
        raise _bad(source, key, tp, value)
    if tp is int:
        if isinstance(value, int) and not isinstance(value, bool):
            return value
        raise _bad(source, key, tp, value)
    if tp is float:
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            if not math.isfinite(value):        # TOML has nan and inf literals
                raise ConfigError(f"{source}: key '{key}' must be a finite number, got {value!r}")
            return float(value)
        raise _bad(source, key, tp, value)
    if tp is str:
        if isinstance(value, str):
            return value
        raise _bad(source, key, tp, value)
    if tp is Path:
        if isinstance(value, str):
            return Path(value)
        raise _bad(source, key, tp, value)
    raise ConfigError(f"{source}: key '{key}' has an unsupported schema type {tp!r}")


def _bad(source: str, key: str, tp: Any, value: Any) -> ConfigError:
    return ConfigError(
        f"{source}: key '{key}' expects {_describe(tp)}, got {_tname(value)} ({value!r:.60})"
    )


def _describe(tp: Any) -> str:
    origin = get_origin(tp)
    args = get_args(tp)
    if origin in (typing.Union, types.UnionType):
        return " or ".join(_describe(a) for a in args if a is not type(None)) + (
            " (optional)" if type(None) in args else "")
    if origin is Literal:
        return "one of " + ", ".join(repr(a) for a in args)
    if origin in (list, tuple):
        if origin is tuple and args and args[-1] is not Ellipsis:
            return f"an array of {len(args)} items"
        return f"an array of {_describe(args[0]) if args else 'values'}"
    if origin is dict:
        return "a table"
    if dataclasses.is_dataclass(tp):
        return f"a table ({tp.__name__})"
    return {bool: "a boolean", int: "an integer", float: "a number", str: "a string",
            Path: "a path string"}.get(tp, getattr(tp, "__name__", str(tp)))


def _tname(value: Any) -> str:
    return {bool: "boolean", int: "integer", float: "float", str: "string", list: "array",
            dict: "table"}.get(type(value), type(value).__name__)


def _join(prefix: str, name: str) -> str:
    return f"{prefix}.{name}" if prefix else name
