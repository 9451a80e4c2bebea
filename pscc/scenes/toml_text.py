"""TOML text for scene files: config dataclasses as TOML data, and a small writer (``tomllib`` only reads)."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import MISSING, Field, fields
from typing import Any

import numpy as np

__all__ = ["config_to_toml", "dump_toml", "field_kind"]


def field_kind(spec_field: Field) -> str:
    """How a config field is written in TOML: vector, bool, int, float, auto_float, str or any."""
    annotation = spec_field.type if isinstance(spec_field.type, str) else str(spec_field.type)
    annotation = annotation.replace(" ", "").replace("typing.", "")
    if annotation.startswith("tuple["):
        return "vector"
    if annotation in ("bool", "int", "float", "str"):
        return annotation
    if annotation in ("float|None", "None|float", "Optional[float]"):
        return "auto_float"
    default = spec_field.default
    if default is MISSING or default is None:
        return "any"
    return {bool: "bool", int: "int", float: "float", str: "str", tuple: "vector"}.get(type(default), "any")


def config_to_toml(config: Any) -> dict[str, Any]:
    """Every field of a config dataclass as TOML data (None -> "auto", tuples -> lists)."""
    out: dict[str, Any] = {}
    for spec_field in fields(config):
        value = getattr(config, spec_field.name)
        if value is None:
            value = "auto"
        elif isinstance(value, tuple):
            value = [float(v) for v in value]
        elif isinstance(value, bool | str):
            pass
        elif isinstance(value, int | np.integer):
            value = int(value)
        elif isinstance(value, float | np.floating):
            value = float(value)
        out[spec_field.name] = value
    return out




def _toml_string(text: str) -> str:
    escapes = {'"': '\\"', "\\": "\\\\", "\b": "\\b", "\t": "\\t", "\n": "\\n", "\f": "\\f", "\r": "\\r"}
    out = []
    for char in text:
        if char in escapes:
            out.append(escapes[char])
        elif ord(char) < 0x20 or ord(char) == 0x7F:
            out.append(f"\\u{ord(char):04x}")
        else:
            out.append(char)
    return '"' + "".join(out) + '"'


def _toml_value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int | np.integer):
        return str(int(value))
    if isinstance(value, float | np.floating):
        number = float(value)
        if not math.isfinite(number):
            raise ValueError(f"cannot write the non-finite number {number!r} to TOML")
        return repr(number)
    if isinstance(value, str):
        return _toml_string(value)
    if isinstance(value, list | tuple):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{ " + ", ".join(f"{k} = {_toml_value(v)}" for k, v in value.items()) + " }"
    raise TypeError(f"cannot write {type(value).__name__} to TOML")


def _is_table_array(value: Any) -> bool:
    return isinstance(value, list) and bool(value) and all(isinstance(v, dict) for v in value)


def _dump_table(table: Mapping[str, Any], prefix: str, lines: list[str]) -> None:
    for name, value in table.items():
        if not isinstance(value, dict) and not _is_table_array(value):
            lines.append(f"{name} = {_toml_value(value)}")
    for name, value in table.items():
        if isinstance(value, dict):
            lines.extend(["", f"[{prefix}{name}]"])
            _dump_table(value, f"{prefix}{name}.", lines)
    for name, value in table.items():
        if _is_table_array(value):
            for item in value:
                lines.extend(["", f"[[{prefix}{name}]]"])
                _dump_table(item, f"{prefix}{name}.", lines)


def dump_toml(data: Mapping[str, Any]) -> str:
    """TOML text of nested dicts, lists of tables and scalars (plain keys first, then tables, then arrays)."""
    lines: list[str] = []
    _dump_table(data, "", lines)
    return "\n".join(lines).lstrip("\n") + "\n"
