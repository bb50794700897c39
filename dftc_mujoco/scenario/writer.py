"""Writing a scenario document as TOML text (floats by ``repr``: read back bit for bit)."""

from __future__ import annotations

import datetime
import math
import re
from collections.abc import Mapping
from typing import Any

import numpy as np

_BARE_KEY = re.compile(r"^[A-Za-z0-9_-]+$")
_ESCAPES = {
    '"': '\\"',
    "\\": "\\\\",
    "\b": "\\b",
    "\t": "\\t",
    "\n": "\\n",
    "\f": "\\f",
    "\r": "\\r",
}


def _dumps(data: Mapping[str, Any]) -> str:
    """A TOML document for ``data``: tables, arrays (of tables), strings, numbers, booleans."""
    lines: list[str] = []
    _emit_table(lines, (), data, "")
    return "\n".join(lines).lstrip("\n") + "\n"


def _emit_table(
    lines: list[str], path: tuple[str, ...], table: Mapping[str, Any], kind: str
) -> None:
    if kind:
        name = ".".join(_toml_key(k) for k in path)
        lines += ["", f"[{name}]" if kind == "table" else f"[[{name}]]"]
    nested = []
    for k, v in table.items():
        if isinstance(v, Mapping) or _is_array_of_tables(v):
            nested.append((k, v))
        else:
            lines.append(f"{_toml_key(k)} = {_toml_value(v)}")
    for k, v in nested:
        if isinstance(v, Mapping):
            _emit_table(lines, (*path, k), v, "table")
        else:
            for item in v:
                _emit_table(lines, (*path, k), item, "array")


def _is_array_of_tables(v: Any) -> bool:
    return isinstance(v, list | tuple) and len(v) > 0 and all(isinstance(x, Mapping) for x in v)


def _toml_key(k: Any) -> str:
    if not isinstance(k, str):
        raise TypeError(f"TOML keys are strings, got {type(k).__name__} {k!r}")
    return k if _BARE_KEY.match(k) else _toml_string(k)


def _toml_string(s: str) -> str:
    out = []
    for ch in s:
        if ch in _ESCAPES:
            out.append(_ESCAPES[ch])
        elif ord(ch) < 0x20 or ord(ch) == 0x7F:
            out.append(f"\\u{ord(ch):04x}")
        else:
            out.append(ch)
    return '"' + "".join(out) + '"'


def _toml_value(v: Any) -> str:
    if isinstance(v, np.generic | np.ndarray):
        v = v.tolist()
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)  # the shortest text that reads back as the same float
    if isinstance(v, str):
        return _toml_string(v)
    if isinstance(v, datetime.date | datetime.time):  # datetime is a date
        return v.isoformat()
    if isinstance(v, list | tuple):
        items = [_toml_value(x) for x in v]
        one_line = "[" + ", ".join(items) + "]"
        if len(one_line) <= 80 or not any(isinstance(x, list | tuple) for x in v):
            return one_line
        return "[\n" + "".join(f"    {item},\n" for item in items) + "]"
    if isinstance(v, Mapping):
        return "{" + ", ".join(f"{_toml_key(k)} = {_toml_value(x)}" for k, x in v.items()) + "}"
    raise TypeError(f"cannot write {type(v).__name__} {v!r} as a TOML value")
