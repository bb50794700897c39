"""Writing a calibration into a robot file's ``[calibration]`` table (or an older MJCF's
``<custom>`` numerics), atomically, changing nothing else.

A robot file is edited through tomlkit, which keeps every other byte of the file: its
comments (a comment above the next table stays there), its layout, its other tables; only
``[calibration]``'s keys are set, added or removed. An MJCF is edited as text: the
``data`` of its ``dftc_*`` numerics, never re-saved through MjSpec (which would inline its
``<include>`` files and rewrite its actuators). Every value the write changes or removes is
returned (:class:`Change`), so that the command lists it before it is lost; ``keep`` keeps
the values the file already has and only adds the keys it lacks.
"""

from __future__ import annotations

import os
import re
import tomllib
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..errors import ScenarioError
from ..runtime.atomic import write_text
from .mismatch import Calibration

MARK = "python -m dftc_mujoco.calibrate --write"
_LEGACY_KEYS = ("mismatch", "xi_bar")  # what an MJCF of the older contract holds


@dataclass(frozen=True)
class Change:
    """A value of the file that a write replaces (``new`` None: removes)."""

    key: str
    old: Any
    new: float | None
    comment: str = ""  # the old value's own comment (it goes with the old value)

    def line(self) -> str:
        said = f" ({self.comment})" if self.comment else ""
        if self.new is None:
            return f"{self.key} = {self.old!r}{said}: removed (not measured this time)"
        return f"{self.key} = {self.old!r}{said} -> {self.new:.6g}"


def values_of(path: Path, cal: Calibration) -> dict[str, float]:
    """What a write of ``cal`` stores in ``path``."""
    if path.name.endswith(".toml"):
        return cal.table()
    return {"mismatch": cal.smooth_max, "xi_bar": cal.recommended_xi_bar}


def write(
    path: Path,
    values: dict[str, float],
    *,
    keep: bool = False,
    complete: bool = True,
    say: Callable[[list[Change]], object] | None = None,
) -> list[Change]:
    """Store ``values`` (:func:`values_of`): the ``[calibration]`` table of a robot file, or
    the ``<custom>`` numerics of an MJCF of the older contract. ``complete``: the values are
    the whole calibration, and a calibration key of the file they lack is removed (a
    partial write only sets and adds). Returns the values of the file it changed (with
    ``keep``, none: existing values stay, missing keys are added), handed to ``say`` first."""
    if path.name.endswith(".toml"):
        text, changes = _robot_file_text(path, path.read_text(encoding="utf-8"), values, keep,
                                         complete)  # fmt: skip
        tomllib.loads(text)  # never write a file that does not read back
    else:
        text, changes = _mjcf_text(path, path.read_text(encoding="utf-8"), values, keep)
    if say is not None and changes:
        say(changes)  # listed before they are replaced
    write_text(path, text)
    return changes


def check_writable(path: Path) -> None:
    """Refuse ``--write`` before measuring when the calibration cannot be written: a robot
    file whose calibration is an inline or dotted table, an MJCF whose numerics are in an
    included file or repeated, or a file or folder without write permission."""
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise ScenarioError(f"{path}: cannot read it to write the calibration: {exc}") from None
    probe = {k: 0.0 for k in _LEGACY_KEYS}
    if path.name.endswith(".toml"):
        _robot_file_text(path, text, probe, True, False)
    else:
        _mjcf_text(path, text, probe, True)
    if not os.access(path, os.W_OK) or not os.access(path.parent, os.W_OK):
        raise ScenarioError(f"{path}: cannot write the calibration there (permission denied)")


# --------------------------------------------------------------------------- robot files


def _format(v: float) -> Any:
    import tomlkit

    return tomlkit.item(float(f"{float(v):.6g}"))


def _robot_file_text(
    path: Path, text: str, values: dict[str, float], keep: bool, complete: bool
) -> tuple[str, list[Change]]:
    import tomlkit
    from tomlkit.items import Item, Table

    from ..sim.robots import CALIBRATION_KEYS

    try:
        doc = tomlkit.parse(text)
    except Exception as exc:  # tomlkit's own error classes: the file is not TOML
        raise ScenarioError(f"{path}: not valid TOML: {exc}") from None
    if "calibration" not in doc:
        block = "\n".join(f"{k} = {_format(v).as_string()}" for k, v in values.items())
        sep = "" if not text or text.endswith("\n") else "\n"
        return f"{text}{sep}\n[calibration]  # {MARK}\n{block}\n", []
    table = doc["calibration"]
    if not isinstance(table, Table) or table.is_super_table():
        raise ScenarioError(
            f"{path}: calibration: written as an inline or dotted table; --write replaces the "
            "keys of a [calibration] table: move those keys into one and run again"
        )
    changes: list[Change] = []
    added: list[str] = []  # new keys: written after the table's last key, below
    container = table.value

    def item(key: str) -> Item:
        found = container.item(key)
        if not isinstance(found, Item):  # a table split in pieces: not a calibration value
            raise ScenarioError(f"{path}: calibration.{key}: expected a number, got a table")
        return found

    for key, value in values.items():
        new = _format(value)
        if key in container:
            old = item(key)
            if keep or old.unwrap() == new.unwrap():
                continue
            changes.append(Change(key, old.unwrap(), float(new.unwrap()), old.trivia.comment))
            container[key] = new
            fresh = item(key)
            fresh.trivia.comment = ""  # the old value's comment described the old value
            fresh.trivia.comment_ws = ""
        else:
            added.append(f"{key} = {new.as_string()}\n")
    if complete and not keep:
        for key in [k for k in CALIBRATION_KEYS if k in container and k not in values]:
            old = item(key)
            changes.append(Change(key, old.unwrap(), None, old.trivia.comment))
            del container[key]
    return _after_last_key(path, doc.as_string(), "".join(added)), changes


#: the header of the robot file's [calibration] table, and of any table
_CALIBRATION_HEADER = re.compile(r"^[ \t]*\[[ \t]*([\"']?)calibration\1[ \t]*\][^\n]*(\n|$)", re.M)
_ANY_HEADER = re.compile(r"^[ \t]*\[")


def _after_last_key(path: Path, text: str, lines: str) -> str:
    """``text`` with ``lines`` inserted after the last key of its [calibration] table: a
    comment or blank line that ends the table belongs to what follows it (the next
    table's own comment), so it stays below them."""
    if not lines:
        return text
    header = _CALIBRATION_HEADER.search(text)
    if header is None:  # a header tomlkit reads that this does not (a unicode escape)
        raise ScenarioError(
            f"{path}: calibration: its table header is not written [calibration]; write it "
            "so and run again"
        )
    at = pos = header.end()
    if not header.group(2):  # the header is the file's last line
        text += "\n"
        at = pos = len(text)
    for line in text[pos:].splitlines(keepends=True):
        if _ANY_HEADER.match(line):
            break
        pos += len(line)
        if line.strip() and not line.lstrip().startswith("#"):
            at = pos  # a key's line (or a multi-line value's)
    if at == len(text) and not text.endswith("\n"):
        lines = "\n" + lines
    return text[:at] + lines + text[at:]


# --------------------------------------------------------------------------- MJCF


def _outside_comments(text: str, pattern: re.Pattern[str]) -> list[re.Match[str]]:
    spans = [m.span() for m in re.finditer(r"<!--.*?-->", text, re.S)]
    return [m for m in pattern.finditer(text) if not any(a <= m.start() < b for a, b in spans)]


def _mjcf_text(
    path: Path, text: str, values: dict[str, float], keep: bool
) -> tuple[str, list[Change]]:
    """The MJCF's text with the ``dftc_*`` numerics' ``data`` set: each element edited in
    place, a missing one added to the first ``<custom>`` (or a new one before
    ``</mujoco>``); every other byte as it was."""
    changes: list[Change] = []
    for key, value in values.items():
        name = f"dftc_{key}"
        element = re.compile(
            r"<numeric\b[^>]*?\bname\s*=\s*([\"'])" + re.escape(name) + r"\1[^>]*?/?>", re.S
        )
        found = _outside_comments(text, element)
        if len(found) > 1:
            raise ScenarioError(
                f"{path}: <numeric name={name!r}> is declared {len(found)} times; MuJoCo keeps "
                "one: delete the others and run again"
            )
        shown = f"{value:.6g}"
        if found:
            tag = found[0].group(0)
            data = re.search(r"\bdata\s*=\s*([\"'])(.*?)\1", tag, re.S)
            said = data.group(2).strip() if data else ""
            try:
                old: Any = float(said.split()[0])
            except (ValueError, IndexError):
                old = said
            if keep or old == float(shown):
                continue
            if data:
                new_tag = tag[: data.start(2)] + shown + tag[data.end(2) :]
            else:
                end = -2 if tag.endswith("/>") else -1
                new_tag = f'{tag[:end].rstrip()} data="{shown}"{tag[end:]}'
            changes.append(Change(key, old, float(shown)))
            text = text[: found[0].start()] + new_tag + text[found[0].end() :]
            continue
        if _declared_elsewhere(path, name):
            raise ScenarioError(
                f"{path}: <numeric name={name!r}> is declared in a file it includes; --write "
                "edits this file only: move the declaration here and run again"
            )
        numeric = f'<numeric name="{name}" data="{shown}"/>'
        custom = _outside_comments(text, re.compile(r"</custom\s*>"))
        if custom:
            at = custom[0].start()
            text = f"{text[:at]}  {numeric}\n  {text[at:]}"
        else:
            closing = _outside_comments(text, re.compile(r"</mujoco\s*>"))
            if not closing:
                raise ScenarioError(f"{path}: no </mujoco> closing tag to add <custom> before")
            at = closing[-1].start()
            text = f"{text[:at]}  <custom>\n    {numeric}\n  </custom>\n{text[at:]}"
    return text, changes


def _declared_elsewhere(path: Path, name: str) -> bool:
    """Whether the model as MuJoCo reads it (its includes too) declares numeric ``name``."""
    import mujoco

    try:
        spec = mujoco.MjSpec.from_file(str(path))
    except Exception as exc:
        raise ScenarioError(f"{path}: MuJoCo cannot read it: {exc}") from None
    return any(n.name == name for n in spec.numerics)
