"""The TOML checker every input file of the package goes through: scenarios, robot files and
campaign specs.

:func:`read_toml` reads a file into a document (one line on a file that is not TOML, not
UTF-8 or unreadable); :class:`Doc` collects every problem of a document, each naming the
file, the dotted key, what was expected and what was found, and raises them all at once
as one :class:`~dftc_mujoco.errors.InputError`; :class:`Table` reads one table's keys
with their types, ranges and defaults.
"""

from __future__ import annotations

import math
import re
import tomllib
from collections.abc import Callable
from pathlib import Path
from typing import Any, NoReturn, TypeVar

import numpy as np

from ..errors import ScenarioError

__all__ = ["Abort", "Doc", "Table", "describe", "read_toml"]

N_DIM = 2  # planar robots: n = 2 in the paper's notation
#: no number of a planar robot team's set-up is larger (in m, s, m/s, counts...): beyond it a
#: value is a typo, and sizes computed from it would overflow
MAGNITUDE = 1e9
_HUGE = " (no quantity of a planar robot team is that large)"
_MISSING = object()
_T = TypeVar("_T")


def _ro(a: Any) -> np.ndarray:
    arr = np.array(a, dtype=float)
    arr.setflags(write=False)
    return arr


class Abort(Exception):
    """Stop reading one key: its error is recorded, or it needs a key that failed."""


def _segments(key: str) -> tuple[str, ...]:
    """``"faults[2].value"`` and ``"faults.2.value"`` -> ``("faults", "2", "value")``."""
    if key == "(top level)":
        return ()
    return tuple(re.findall(r"[^.\[\]]+", key))


def _nested(a: tuple[str, ...], b: tuple[str, ...]) -> bool:
    """True when one of two keys is the other or holds it."""
    n = min(len(a), len(b))
    return a[:n] == b[:n]


class Doc:
    """The problems found in one document, kept in file order."""

    def __init__(self, file: str, data: Any, overridden: tuple[str, ...] = ()):
        self.file = file
        self.data = data
        self.problems: list[tuple[tuple[int, ...], int, str]] = []
        self.failed: list[tuple[str, ...]] = []
        self.overridden = [_segments(k) for k in overridden]

    def record(self, where: str, message: str) -> None:
        """Record that key ``where`` (e.g. ``"faults[2].t"``) is wrong."""
        segs = _segments(where)
        self.failed.append(segs)
        label = self.file
        if any(_nested(segs, o) for o in self.overridden):
            label += " (override)"
        self.problems.append(
            (self._position(segs), len(self.problems), f"{label}: {where}: {message}")
        )

    def ok(self, *keys: str) -> bool:
        """True when no key among ``keys``, no table holding one, and nothing in one failed."""
        return not any(_nested(_segments(k), f) for k in keys for f in self.failed)

    def guard(self, fn: Callable[..., _T], *args: Any) -> _T | None:
        """``fn(*args)``, or None when it stops at a recorded error."""
        try:
            return fn(*args)
        except Abort:
            return None
        except Exception:
            if self.problems:  # a consequence of a recorded error: that error explains it
                return None
            raise

    def _position(self, segs: tuple[str, ...]) -> tuple[int, ...]:
        """Where a key is in the file; a missing key sorts after its table's keys."""
        pos: list[int] = []
        node = self.data
        for s in segs:
            if isinstance(node, dict):
                keys = list(node)
                if s not in node:
                    pos.append(len(keys))
                    break
                pos.append(keys.index(s))
                node = node[s]
            elif isinstance(node, list) and s.isdigit() and 1 <= int(s) <= len(node):
                pos.append(int(s) - 1)
                node = node[int(s) - 1]
            else:
                break
        return tuple(pos)

    def raise_problems(self) -> None:
        if self.problems:
            raise ScenarioError("\n".join(line for _, _, line in sorted(self.problems)))


class Table:
    """A TOML table read key by key; unread keys are reported as unknown.

    Without a ``doc`` the first problem raises :class:`ScenarioError`. With one,
    problems are recorded there: a reader whose key is wrong returns its
    default (or a placeholder) and the key is marked failed, so that the
    checks which need it can be skipped (:meth:`ok`).
    """

    def __init__(self, file: str, data: Any, path: str, doc: Doc | None = None):
        self.file = file
        self.path = path
        self.doc = doc
        self.data = data if isinstance(data, dict) else {}
        self.used: set[str] = set()
        if not isinstance(data, dict):
            self.fail("", f"expected a table, got {describe(data)}")

    def key(self, name: str) -> str:
        return f"{self.path}.{name}" if self.path else name

    def report(self, name: str, message: str) -> None:
        """Record a problem with key ``name`` (raise it at once without a doc)."""
        where = self.key(name) if name else (self.path or "(top level)")
        if self.doc is None:
            raise ScenarioError(f"{self.file}: {where}: {message}")
        self.doc.record(where, message)

    def fail(self, name: str, message: str) -> NoReturn:
        """Report a problem with key ``name`` and stop reading that key."""
        self.report(name, message)
        raise Abort(name)

    def ok(self, *names: str) -> bool:
        """True when none of these keys failed."""
        return self.doc is None or self.doc.ok(*(self.key(n) for n in names))

    def given(self, name: str) -> bool:
        """Whether optional key ``name`` is in the table (a known key either way: an unknown
        key's message lists it)."""
        self.used.add(name)
        return name in self.data

    def raw(self, name: str, default: Any = _MISSING) -> Any:
        self.used.add(name)
        if name not in self.data:
            if default is _MISSING:
                self.fail(name, "missing key")
            return default
        return self.data[name]

    def number(
        self,
        name: str,
        default: Any = _MISSING,
        *,
        low: float | None = None,
        strict_low: bool = True,
        high: float | None = None,
    ) -> float:
        try:
            v = self.raw(name, default)
            if isinstance(v, bool) or not isinstance(v, int | float):
                self.fail(name, f"expected a number, got {describe(v)}")
            v = float(v)
            if not math.isfinite(v):
                self.fail(name, f"expected a finite number, got {v}")
            if abs(v) > MAGNITUDE:
                self.fail(name, f"expected a number within ±{MAGNITUDE:g}, got {v:g}{_HUGE}")
            if low is not None and (v <= low if strict_low else v < low):
                self.fail(
                    name, f"expected a number {'>' if strict_low else '>='} {low:g}, got {v:g}"
                )
            if high is not None and v > high:
                self.fail(name, f"expected a number <= {high:g}, got {v:g}")
            return v
        except Abort:
            return 1.0 if default is _MISSING else float(default)

    def integer(
        self,
        name: str,
        default: Any = _MISSING,
        *,
        low: int | None = None,
        high: int | None = None,
    ) -> int:
        try:
            v = self.raw(name, default)
            if isinstance(v, bool) or not isinstance(v, int):
                self.fail(name, f"expected an integer, got {describe(v)}")
            if low is not None and v < low:
                self.fail(name, f"expected an integer >= {low}, got {v}")
            if high is not None and v > high:
                self.fail(name, f"expected an integer <= {high}, got {v}")
            if high is None and abs(v) > MAGNITUDE:  # seeds say their own range
                self.fail(name, f"expected an integer within ±{MAGNITUDE:g}, got {v:g}{_HUGE}")
            return int(v)
        except Abort:
            return (low or 0) if default is _MISSING else int(default)

    def string(self, name: str, default: Any = _MISSING, *, choices: tuple[str, ...] = ()) -> str:
        try:
            v = self.raw(name, default)
            if not isinstance(v, str):
                self.fail(name, f"expected a string, got {describe(v)}")
            if choices and v not in choices:
                self.fail(name, f"expected one of {', '.join(map(repr, choices))}, got {v!r}")
            return v
        except Abort:
            return "" if default is _MISSING else default

    def boolean(self, name: str, default: Any = _MISSING) -> bool:
        try:
            v = self.raw(name, default)
            if not isinstance(v, bool):
                self.fail(name, f"expected true or false, got {describe(v)}")
            return v
        except Abort:
            return False if default is _MISSING else default

    def array(
        self, name: str, shape: tuple[int | None, ...], default: Any = _MISSING, what: str = ""
    ) -> np.ndarray:
        """A numeric array; ``None`` in ``shape`` accepts any length >= 1."""
        try:
            v = self.raw(name, default)
            arr = _numeric_array(v)
            want = what or _shape_words(shape)
            if (
                arr is None
                or arr.ndim != len(shape)
                or any(
                    (s is not None and s != a) or a == 0
                    for s, a in zip(shape, arr.shape, strict=True)
                )
            ):
                self.fail(name, f"expected {want}, got {describe(v)}")
            if not np.all(np.isfinite(arr)):
                self.fail(name, f"expected finite numbers, got {v!r}")
            if np.abs(arr).max() > MAGNITUDE:
                big = float(np.abs(arr).max())
                self.fail(name, f"expected numbers within ±{MAGNITUDE:g}, got {big:g}{_HUGE}")
            return _ro(arr)
        except Abort:
            if default is not _MISSING:
                return _ro(default)
            return _ro(np.zeros([1 if s is None else s for s in shape]))

    def gain_matrix(self, name: str, auto: bool = False) -> np.ndarray:
        """A scalar (meaning scalar x I) or a symmetric positive definite 2x2 matrix
        (``auto``: the word "auto" is also accepted, by the caller)."""
        what = "a positive number" + (', "auto"' if auto else "") + " or a 2x2 matrix"
        try:
            v = self.raw(name)
            scalar = isinstance(v, int | float) and not isinstance(v, bool)
            if scalar and not (v > 0 and math.isfinite(v)):
                self.fail(name, f"expected {what}, got {v}")
            m = np.array(float(v)) if scalar else _numeric_array(v)
            if m is None or m.shape not in ((), (N_DIM, N_DIM)):
                self.fail(name, f"expected {what}, got {describe(v)}")
            if np.abs(m).max() > MAGNITUDE:  # as number() says it (an inf fails above)
                said = f"{np.abs(m).max():g}{_HUGE}"
                self.fail(name, f"expected numbers within ±{MAGNITUDE:g}, got {said}")
            if m.shape == ():
                return _ro(float(m) * np.eye(N_DIM))
            if (
                not np.all(np.isfinite(m))
                or not np.allclose(m, m.T)
                or np.linalg.eigvalsh(m).min() <= 0
            ):
                self.fail(name, f"expected a symmetric positive definite matrix, got {v!r}")
            return _ro(m)
        except Abort:
            return _ro(np.eye(N_DIM))

    def table(self, name: str, default: Any = _MISSING) -> Table:
        return Table(self.file, self.raw(name, default), self.key(name), self.doc)

    def tables(self, name: str) -> list[Table]:
        v = self.raw(name, [])
        if not isinstance(v, list) or not all(isinstance(x, dict) for x in v):
            self.fail(name, f"expected an array of tables ([[{name}]]), got {describe(v)}")
        return [
            Table(self.file, x, f"{self.key(name)}[{k + 1}]", self.doc) for k, x in enumerate(v)
        ]

    def finish(self) -> None:
        """Report the keys nobody read (all of them with a doc, the first without)."""
        unknown = [k for k in self.data if k not in self.used]
        if unknown:
            known = ", ".join(sorted(self.used)) or "none"
            for name in sorted(unknown) if self.doc is None else unknown:
                self.report(name, f"unknown key (known keys here: {known})")


def _numeric_array(v: Any) -> np.ndarray | None:
    def ok(x: Any) -> bool:
        if isinstance(x, list):
            return all(ok(y) for y in x)
        return isinstance(x, int | float) and not isinstance(x, bool)

    if not isinstance(v, list) or not ok(v):
        return None
    try:
        return np.array(v, dtype=float)
    except ValueError:  # ragged
        return None


def _shape_words(shape: tuple[int | None, ...]) -> str:
    dims = " x ".join("N" if s is None else str(s) for s in shape)
    return f"a numeric array of shape {dims}"


def describe(v: Any) -> str:
    if isinstance(v, dict):
        return "a table"
    if isinstance(v, list):
        return f"{v!r}" if len(repr(v)) < 60 else f"a list of {len(v)} items"
    return f"{type(v).__name__} {v!r}"


def read_toml(path: Path) -> dict[str, Any]:
    try:
        with open(path, "rb") as fh:
            return tomllib.load(fh)
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(f"{path}: not valid TOML: {exc}") from None
    except RecursionError:
        raise ScenarioError(
            f"{path}: not a usable TOML file: its arrays or tables are nested too deep"
        ) from None
    except UnicodeDecodeError as exc:
        raise ScenarioError(
            f"{path}: not UTF-8 text (byte 0x{exc.object[exc.start]:02x} at offset "
            f"{exc.start}); TOML files must be UTF-8"
        ) from None
    except OSError as exc:
        raise ScenarioError(f"{path}: cannot read: {exc.strerror}") from None


def number_or_word(
    t: Table,
    name: str,
    word: str,
    what: str,
    absent: float | None = None,
    low: float = 0.0,
    strict_low: bool = True,
) -> float | str:
    """Key ``name``: a number (at least ``low``), or the keyword ``word``; absent, ``absent``
    (``word`` when None). A string other than ``word`` says it expected ``what``."""
    raw = t.data.get(name, word if absent is None else absent)
    if isinstance(raw, str):
        t.raw(name, word)
        if raw != word:
            t.report(name, f'expected {what} or "{word}", got {raw!r}')
        return word
    return t.number(name, 0.0 if absent is None else absent, low=low, strict_low=strict_low)
