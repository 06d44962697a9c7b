"""Typed configuration from YAML: dataclasses validated field by field, with clear errors.

Every configurable object in the project is a frozen dataclass whose fields carry their
constraints in ``spec(...)`` metadata. :func:`from_mapping` turns a plain mapping (parsed
YAML) into such a dataclass, refusing unknown keys, wrong types, non-finite numbers and
out-of-range values with a :class:`ConfigError` that names the file, the key path, the value
and what is allowed.

Example
-------
>>> from dataclasses import dataclass
>>> @dataclass(frozen=True)
... class Hover:
...     altitude_m: float = spec(5.0, minimum=0.0, doc="height above the anchor")
>>> from_mapping(Hover, {"altitude_m": 2.0}, source="demo.yaml")
Hover(altitude_m=2.0)
"""

from __future__ import annotations

import dataclasses
import math
import os
import stat
import types
import typing
from collections.abc import Mapping
from pathlib import Path
from typing import Any, TypeVar

import yaml

T = TypeVar("T")

_MISSING = dataclasses.MISSING
MAX_YAML_BYTES = 1 << 20
"""A YAML file larger than this [bytes] is refused before it is read (configs are ~10 kB)."""


class ConfigError(ValueError):
    """A configuration value is missing, unknown, of the wrong type or out of range.

    The message always names the source (file), the key path, the value and what is allowed.
    """

    def __init__(self, source: str, key: str, value: object, allowed: str) -> None:
        self.source = source
        self.key = key
        self.value = value
        self.allowed = allowed
        shown = "<missing>" if value is _MISSING else repr(value)
        where = f"{source}: " if source else ""
        super().__init__(f"{where}{key or '<top level>'} = {shown}: {allowed}")


def spec(
    default: Any = _MISSING,
    *,
    default_factory: Any = _MISSING,
    minimum: float | None = None,
    maximum: float | None = None,
    exclusive_minimum: float | None = None,
    exclusive_maximum: float | None = None,
    choices: tuple[Any, ...] | None = None,
    length: int | None = None,
    doc: str = "",
) -> Any:
    """A dataclass field with validation metadata.

    Parameters
    ----------
    default, default_factory
        As for :func:`dataclasses.field`; with neither the key is required.
    minimum, maximum
        Inclusive bounds for numbers (applied element-wise to tuples of numbers).
    exclusive_minimum, exclusive_maximum
        Exclusive bounds for numbers (e.g. ``exclusive_minimum=0`` for "strictly positive").
    choices
        The allowed values for strings (or any scalar).
    length
        Required length of a tuple field.
    doc
        One line saying what the value is, with its unit; shown in docs and errors.
    """
    metadata = {
        "minimum": minimum,
        "maximum": maximum,
        "exclusive_minimum": exclusive_minimum,
        "exclusive_maximum": exclusive_maximum,
        "choices": choices,
        "length": length,
        "doc": doc,
    }
    if default_factory is not _MISSING:
        return dataclasses.field(default_factory=default_factory, metadata=metadata)
    return dataclasses.field(default=default, metadata=metadata)


def _describe_range(meta: Mapping[str, Any]) -> str:
    parts = []
    if meta.get("minimum") is not None:
        parts.append(f">= {meta['minimum']}")
    if meta.get("exclusive_minimum") is not None:
        parts.append(f"> {meta['exclusive_minimum']}")
    if meta.get("maximum") is not None:
        parts.append(f"<= {meta['maximum']}")
    if meta.get("exclusive_maximum") is not None:
        parts.append(f"< {meta['exclusive_maximum']}")
    return " and ".join(parts)


def _check_number(value: float, meta: Mapping[str, Any], source: str, key: str, kind: str) -> None:
    """Refuse a non-finite ``value`` or one outside the field's bounds (``value`` as given)."""
    if not math.isfinite(value):
        raise ConfigError(source, key, value, f"must be a finite {kind}")
    lo, hi = meta.get("minimum"), meta.get("maximum")
    xlo, xhi = meta.get("exclusive_minimum"), meta.get("exclusive_maximum")
    out = (
        (lo is not None and value < lo)
        or (hi is not None and value > hi)
        or (xlo is not None and value <= xlo)
        or (xhi is not None and value >= xhi)
    )
    if out:
        article = "an" if kind[0] in "aeiou" else "a"
        raise ConfigError(source, key, value, f"must be {article} {kind} {_describe_range(meta)}")


def _convert(tp: Any, value: Any, meta: Mapping[str, Any], source: str, key: str) -> Any:
    """Convert and validate ``value`` against the annotation ``tp``."""
    origin = typing.get_origin(tp)
    if origin in (typing.Union, types.UnionType):
        options = typing.get_args(tp)
        if value is None and type(None) in options:
            return None
        non_none = [o for o in options if o is not type(None)]
        errors = []
        for option in non_none:
            try:
                return _convert(option, value, meta, source, key)
            except ConfigError as exc:
                errors.append(exc.allowed)
        raise ConfigError(source, key, value, " or ".join(errors))
    if origin is typing.Literal:
        allowed = typing.get_args(tp)
        if value not in allowed:
            raise ConfigError(source, key, value, f"must be one of {', '.join(map(repr, allowed))}")
        return value
    if dataclasses.is_dataclass(tp):
        if not isinstance(value, Mapping):
            raise ConfigError(source, key, value, "must be a mapping of keys to values")
        return from_mapping(tp, value, source=source, prefix=key)
    if origin is tuple:
        args = typing.get_args(tp)
        if not isinstance(value, (list, tuple)):
            raise ConfigError(source, key, value, "must be a list")
        length = meta.get("length")
        if len(args) == 2 and args[1] is Ellipsis:
            item_types = [args[0]] * len(value)
        else:
            item_types = list(args)
            length = len(args)
        if length is not None and len(value) != length:
            raise ConfigError(source, key, value, f"must be a list of {length} items")
        return tuple(
            _convert(item_tp, item, meta, source, f"{key}[{i}]")
            for i, (item_tp, item) in enumerate(zip(item_types, value, strict=True))
        )
    if origin in (dict, Mapping):
        key_tp, value_tp = typing.get_args(tp)
        if not isinstance(value, Mapping):
            raise ConfigError(source, key, value, "must be a mapping")
        return {
            _convert(key_tp, k, {}, source, f"{key}.{k}"): _convert(
                value_tp, v, meta, source, f"{key}.{k}"
            )
            for k, v in value.items()
        }
    if tp is bool:
        if not isinstance(value, bool):
            raise ConfigError(source, key, value, "must be true or false")
        return value
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(
                source, key, value, f"must be an integer {_describe_range(meta)}".strip()
            )
        _check_number(value, meta, source, key, "integer")
        return value
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigError(
                source, key, value, f"must be a number {_describe_range(meta)}".strip()
            )
        _check_number(float(value), meta, source, key, "number")
        return float(value)
    if tp is str:
        if not isinstance(value, str):
            raise ConfigError(source, key, value, "must be a string")
        choices = meta.get("choices")
        if choices is not None and value not in choices:
            raise ConfigError(source, key, value, f"must be one of {', '.join(map(repr, choices))}")
        return value
    raise TypeError(f"config field {key}: unsupported annotation {tp!r}")  # programming error


def from_mapping(cls: type[T], data: Mapping[str, Any], *, source: str = "", prefix: str = "") -> T:
    """Build the dataclass ``cls`` from ``data``, validating every key.

    Parameters
    ----------
    cls
        A dataclass whose fields use :func:`spec` (plain fields are accepted too).
    data
        Parsed YAML (or any mapping). Keys absent from ``data`` take the field default.
    source
        Where the data came from (a file path), used in error messages.
    prefix
        Key path of ``data`` inside the file, used in error messages.

    Raises
    ------
    ConfigError
        On unknown keys, missing required keys, wrong types, non-finite or out-of-range values.
    """
    if not isinstance(data, Mapping):
        raise ConfigError(source, prefix, data, "must be a mapping of keys to values")
    hints = typing.get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls) if f.init}
    for name in data:
        if name not in fields:
            allowed = ", ".join(sorted(fields))
            raise ConfigError(
                source,
                _join(prefix, str(name)),
                data[name],
                f"unknown key; allowed keys: {allowed}",
            )
    kwargs = {}
    for name, field in fields.items():
        key = _join(prefix, name)
        if name in data:
            kwargs[name] = _convert(hints[name], data[name], field.metadata, source, key)
        elif field.default is _MISSING and field.default_factory is _MISSING:
            raise ConfigError(source, key, _MISSING, "is required")
    instance = cls(**kwargs)
    validate = getattr(instance, "validate", None)
    if callable(validate):
        try:
            validate()
        except ConfigError as exc:
            raise ConfigError(source, _join(prefix, exc.key), exc.value, exc.allowed) from None
    return instance


def _join(prefix: str, name: str) -> str:
    return f"{prefix}.{name}" if prefix else name


def read_yaml(path: str | Path) -> Mapping[str, Any]:
    """Parse a YAML file into a mapping (an empty file is an empty mapping).

    Raises
    ------
    ConfigError
        When the file is missing, unreadable, not YAML, or not a mapping at the top level.
    """
    path = Path(path)
    text = _read_small_text(path)
    try:
        data = yaml.safe_load(text)
    except RecursionError:
        raise ConfigError(str(path), "", _MISSING, "not valid YAML: nested too deeply") from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        problem = getattr(exc, "problem", None) or str(exc)
        raise ConfigError(str(path), "", _MISSING, f"not valid YAML{where}: {problem}") from None
    if data is None:
        return {}
    if not isinstance(data, Mapping):
        raise ConfigError(str(path), "", data, "the file must hold a mapping of keys to values")
    return data


def _read_small_text(path: Path) -> str:
    """The UTF-8 text of a regular file of at most :data:`MAX_YAML_BYTES` (checked before
    reading, so a device such as /dev/zero or a huge file is never loaded)."""
    try:
        with path.open("rb") as handle:
            info = os.fstat(handle.fileno())
            if not stat.S_ISREG(info.st_mode):
                raise ConfigError(str(path), "", _MISSING, "not a regular file")
            if info.st_size > MAX_YAML_BYTES:
                raise ConfigError(
                    str(path),
                    "",
                    _MISSING,
                    f"file too large ({info.st_size} bytes; at most {MAX_YAML_BYTES})",
                )
            data = handle.read(MAX_YAML_BYTES + 1)
    except FileNotFoundError:
        raise ConfigError(str(path), "", _MISSING, "file not found") from None
    except IsADirectoryError:
        raise ConfigError(str(path), "", _MISSING, "not a regular file (a directory)") from None
    except OSError as exc:
        raise ConfigError(str(path), "", _MISSING, f"cannot read file ({exc.strerror})") from None
    if len(data) > MAX_YAML_BYTES:
        raise ConfigError(str(path), "", _MISSING, f"file too large (at most {MAX_YAML_BYTES})")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ConfigError(
            str(path), "", _MISSING, f"not UTF-8 text (byte {exc.start}: {exc.reason})"
        ) from None


def load_yaml(cls: type[T], path: str | Path) -> T:
    """Read ``path`` and build the dataclass ``cls`` from it (see :func:`from_mapping`)."""
    return from_mapping(cls, read_yaml(path), source=str(path))


def describe(cls: type) -> list[tuple[str, str, str, str]]:
    """Rows ``(key, type, default, constraint and doc)`` for every field, recursively.

    Used to generate the config reference in docs and ``--help`` output.
    """
    rows: list[tuple[str, str, str, str]] = []

    def walk(klass: type, prefix: str) -> None:
        klass_hints = typing.get_type_hints(klass)
        for field in dataclasses.fields(klass):
            key = _join(prefix, field.name)
            tp = klass_hints[field.name]
            if dataclasses.is_dataclass(tp):
                walk(tp, key)
                continue
            if field.default is not _MISSING:
                default = repr(field.default)
            elif field.default_factory is not _MISSING:
                default = repr(field.default_factory())
            else:
                default = "(required)"
            meta = field.metadata
            constraint = _describe_range(meta)
            if meta.get("choices"):
                constraint = "one of " + ", ".join(map(repr, meta["choices"]))
            text = "; ".join(x for x in (constraint, meta.get("doc", "")) if x)
            rows.append((key, _type_name(tp), default, text))

    walk(cls, "")
    return rows


def _type_name(tp: Any) -> str:
    return getattr(tp, "__name__", None) or str(tp).replace("typing.", "")
