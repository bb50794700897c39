"""A campaign folder belongs to one campaign.

The folder's ``campaign.json`` records the campaign's *identity*: a SHA-256 of
everything that decides what run i is, namely the spec's ``name``, ``seed``,
``[set]`` and ``[vary]`` (as validated), the base scenario's content (its parsed
TOML, wherever the file lives) and the content of every other file the runs read
(:mod:`.inputs`: robot files and their calibration, their MJCF with its includes and
assets, the modules of plug-in blocks). Running the same campaign again into the folder
resumes it; a different spec, the same spec over an edited base scenario, or over a
robot file, MJCF or plug-in that changed since, is refused (naming it) unless
``--overwrite``, which replaces the folder as a whole.

Not part of the identity: ``runs`` and ``--runs`` (run i's parameters depend on the
campaign seed and i alone, so a larger number extends the campaign and a smaller one
reports on its first runs), ``description``, comments and the spec file's path. The
simulator's own code is not hashed: ``campaign.json`` names the dftc-mujoco version that
created the folder. A folder whose identity predates the inputs is resumed when the rest
agrees, and its identity completed.

A folder written before identities existed (``results.jsonl`` but no
``campaign.json``) is adopted when every recorded run has the parameters and
duration this spec gives it, and refused otherwise.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import tempfile
from pathlib import Path
from typing import Any

from .. import __version__
from ..core.record import write_text
from ..errors import OutputError
from ..runtime.output import os_problem, special_file
from .inputs import inputs
from .spec import Spec, draw, scenario_dict

IDENTITY = "campaign.json"
CAMPAIGN_FILES = (IDENTITY, "results.jsonl", "results.parquet", "report.md")


def identity(spec: Spec, with_inputs: bool = True) -> dict[str, Any]:
    """What decides the rows of a campaign (see the module's docstring)."""
    out = {
        "name": spec.name,
        "seed": spec.seed,
        "set": spec.set,
        "vary": spec.vary,
        "base": spec.base,
    }
    if with_inputs:
        out["inputs"] = inputs(spec)
    return out


def fingerprint(spec: Spec, with_inputs: bool = True) -> str:
    """SHA-256 of :func:`identity`, as canonical JSON."""
    return _hash(identity(spec, with_inputs))


def _hash(ident: dict[str, Any]) -> str:
    text = json.dumps(ident, sort_keys=True, separators=(",", ":"), default=str)
    return hashlib.sha256(text.encode()).hexdigest()


def _changed_inputs(stored: dict[str, Any], mine: dict[str, Any]) -> str | None:
    """When two identities differ in their inputs alone: which files, in words."""
    before = stored.get("identity", {})
    if not isinstance(before, dict) or not isinstance(before.get("inputs"), dict):
        return None
    rest = {k: v for k, v in before.items() if k != "inputs"}
    if _hash(rest) != fingerprint_of_rest(mine):
        return None
    old, new = before["inputs"], mine["inputs"]
    said = [
        f"{k} {'changed' if k in old and k in new else 'is new' if k in new else 'is gone'}"
        for k in sorted(old.keys() | new.keys())
        if old.get(k) != new.get(k)
    ]
    return ", ".join(said[:4]) + (f" and {len(said) - 4} more" if len(said) > 4 else "")


def fingerprint_of_rest(ident: dict[str, Any]) -> str:
    """The hash of an identity without its inputs (an identity written before them)."""
    return _hash({k: v for k, v in ident.items() if k != "inputs"})


def _flat(d: Any, prefix: str = "") -> dict[str, Any]:
    if not isinstance(d, dict):
        return {prefix: d}
    out: dict[str, Any] = {}
    for k, v in d.items():
        out.update(_flat(v, f"{prefix}.{k}" if prefix else str(k)))
    return out


def differences(a: dict[str, Any], b: dict[str, Any], most: int = 4) -> str:
    """The dotted keys in which two identities differ, for the error line."""
    fa, fb = _flat(json.loads(json.dumps(a, default=str))), _flat(b)
    keys = sorted(k for k in fa.keys() | fb.keys() if fa.get(k) != fb.get(k))
    keys = [k.replace("base.", "base scenario: ", 1) for k in keys]
    more = f" and {len(keys) - most} more" if len(keys) > most else ""
    return ", ".join(keys[:most]) + more


def _matches_rows(out: Path, spec: Spec) -> bool:
    """A folder without an identity: do its rows have this spec's parameters?"""
    try:
        lines = (out / "results.jsonl").read_text().splitlines()
    except (OSError, UnicodeDecodeError):
        return False
    for line in lines:
        try:
            row = json.loads(line)
            params = draw(spec, int(row["run"]))
        except (ValueError, KeyError, TypeError):
            continue  # a torn line: the store drops it
        if any(row.get(k) != v for k, v in params.items()):
            return False
        if row.get("status") == "ok" and row.get("duration") != scenario_dict(spec, params).get(
            "duration"
        ):
            return False
    return True


def prepare(out: Path, spec: Spec, overwrite: bool) -> str:
    """Make ``out`` the folder of ``spec``'s campaign (call with its lock held).

    Returns what happened: "new", "resumed" or "replaced". Raises OutputError (one
    line) when ``out`` is a file, holds something that is not a campaign, or holds
    another campaign and ``overwrite`` is False.
    """
    out = Path(out).absolute()
    if out.exists() and not out.is_dir():
        raise OutputError(f"{out}: --out names a file, not a folder; choose a folder")
    ident = identity(spec)
    mine = _hash(ident)
    state = "new"
    special = special_file(out) if out.is_dir() else None
    if special is not None:  # reading it would wait forever (a FIFO) or without end
        raise OutputError(
            f"{out}: {special}, not a file this campaign wrote; a campaign folder holds only "
            "regular files and folders: remove it, or choose another --out"
        )
    if out.is_dir() and any(out.iterdir()):
        stored = _stored(out)
        if stored is not None and stored.get("fingerprint") == mine and not overwrite:
            return "resumed"
        before = stored.get("identity") if stored is not None else None
        old_style = isinstance(before, dict) and "inputs" not in before
        if (
            stored is not None
            and old_style
            and stored.get("fingerprint") == fingerprint_of_rest(ident)
            and not overwrite
        ):
            _write_identity(out, spec, mine, ident)  # written before inputs were hashed
            return "resumed"
        changed = _changed_inputs(stored, ident) if stored is not None else None
        if stored is not None and changed and not overwrite:
            raise OutputError(
                f"{out}: the campaign {stored.get('name')!r} ran with other inputs: {changed} "
                "since its rows were written (SHA-256 of the content); resuming would mix rows "
                "of both: put the file back as it was, use --overwrite to run the campaign "
                "again from scratch, or choose another --out"
            )
        if stored is None and not (out / "results.jsonl").exists():
            raise OutputError(
                f"{out}: the folder is not empty and holds no campaign; choose another --out "
                "(it is never replaced, even with --overwrite)"
            )
        if stored is None and _matches_rows(out, spec) and not overwrite:
            _write_identity(out, spec, mine, ident)
            return "resumed"
        if not overwrite:
            what = (
                f"the campaign {stored.get('name')!r} of another spec (differs in: "
                f"{differences(stored.get('identity', {}), ident)})"
                if stored is not None
                else "rows of another campaign"
            )
            raise OutputError(
                f"{out}: holds {what}; use --overwrite to replace it as a whole, "
                "or choose another --out"
            )
        _set_aside_and_remove(out)
        state = "replaced"
    try:
        out.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(spec.source, out / "spec.toml")
        shutil.copyfile(spec.base_source, out / "base_scenario.toml")
    except OSError as exc:
        raise os_problem(exc, "creating the campaign folder") from None
    _write_identity(out, spec, mine, ident)
    return state


def _stored(out: Path) -> dict[str, Any] | None:
    path = out / IDENTITY
    if not path.exists():
        return None
    try:
        stored = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise OutputError(
            f"{path}: unreadable ({exc}); use --overwrite to replace the folder, "
            "or choose another --out"
        ) from None
    if not isinstance(stored, dict):
        raise OutputError(f"{path}: not a campaign identity; use --overwrite or another --out")
    return stored


def _write_identity(out: Path, spec: Spec, mine: str, ident: dict[str, Any]) -> None:
    record = {
        "fingerprint": mine,
        "name": spec.name,
        "spec": str(Path(spec.source).absolute()),
        "base_scenario": str(Path(spec.base_source).absolute()),
        "dftc_mujoco": __version__,
        "identity": ident,
    }
    try:
        write_text(out / IDENTITY, json.dumps(record, indent=2, default=str) + "\n")
    except OSError as exc:
        raise os_problem(exc, "writing campaign.json") from None


def _set_aside_and_remove(out: Path) -> None:
    """Replace ``out`` as a whole: rename it aside (one step), then delete it."""
    try:
        old = Path(tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".old", dir=out.parent))
        os.rmdir(old)
        os.rename(out, old)
    except OSError as exc:
        raise os_problem(exc, "replacing the campaign folder") from None
    shutil.rmtree(old, ignore_errors=True)
