"""The files a campaign's runs read besides its spec and base scenario, by content.

A run reads its robot files (``team.robot_model``: the base scenario's, ``[set]``'s, any
drawn by ``[vary]``), the MJCF each names with the files it includes and the meshes,
textures and height fields it loads, and the modules of its plug-in blocks
(``onboard.BLOCK = "module:Class"``, ``[methods]``). :func:`inputs` hashes each: a
campaign's identity (:mod:`.folder`) holds them, so that a campaign whose robot file,
calibration, MJCF or plug-in changed is not resumed into rows of the old ones.
"""

from __future__ import annotations

import hashlib
import re
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from ..errors import ScenarioError
from .spec import Spec, draw, scenario_dict

_INCLUDE = re.compile(r"<include\b[^>]*?\bfile\s*=\s*([\"'])(.*?)\1", re.S)


def _digest(path: Path) -> str:
    try:
        return hashlib.sha256(path.read_bytes()).hexdigest()
    except OSError as exc:
        return f"unreadable ({exc.strerror})"


def _scenarios(spec: Spec) -> Iterator[dict[str, Any]]:
    """Scenario documents that between them hold every robot model and block a run can
    have: each method's first draw, and run 0 with each choice of each dotted key."""
    methods = len(spec.vary.get("methods", {})) or 1
    for i in range(min(spec.runs, methods)):
        yield scenario_dict(spec, draw(spec, i))
    first = draw(spec, 0)
    for key, choices in spec.vary.get("scenario_keys", {}).items():
        for choice in choices:
            try:
                yield scenario_dict(spec, {**first, key: choice})
            except ScenarioError:  # refused when the spec was read
                continue


def _models(doc: dict[str, Any]) -> list[str]:
    team = doc.get("team", {})
    given = team.get("robot_model", "disk") if isinstance(team, dict) else "disk"
    names = given if isinstance(given, list) else [given]
    return [n for n in names if isinstance(n, str)]


def _modules(doc: dict[str, Any]) -> list[str]:
    from ..blocks import BUILTIN

    onboard = doc.get("onboard", {})
    if not isinstance(onboard, dict):
        return []
    out = []
    for block, builtin in BUILTIN.items():
        name = onboard.get(block)
        if isinstance(name, str) and name not in builtin and ":" in name:
            out.append(name.partition(":")[0])
    return out


def _mjcf_files(mjcf: Path) -> list[Path]:
    """The MJCF, the files it includes (recursively) and the asset files it loads."""
    files, todo = [], [mjcf]
    while todo:
        f = todo.pop()
        if f in files or not f.is_file():
            continue
        files.append(f)
        try:
            text = f.read_text(encoding="utf-8", errors="replace")
        except OSError:
            continue
        todo += [(f.parent / m.group(2)).resolve() for m in _INCLUDE.finditer(text)]
    try:
        from ..sim.robots import _read_spec

        spec: Any = _read_spec(mjcf, mjcf, None)  # asset paths made absolute
    except ScenarioError:
        return files
    for group in (spec.meshes, spec.textures, spec.hfields):
        for asset in group:
            name = getattr(asset, "file", "")
            if name and Path(name).is_file() and Path(name) not in files:
                files.append(Path(name))
    return files


def _module_file(module: str, folders: list[Path]) -> Path | None:
    """Where ``import module`` finds it (sys.path first, then the campaign's folders, as a
    run imports it), without importing it."""
    parts = module.split(".")
    for base in [*map(str, sys.path), *map(str, folders)]:
        root = Path(base or ".", *parts)
        for candidate in (root.with_suffix(".py"), root / "__init__.py"):
            if candidate.is_file():
                return candidate.resolve()
    return None


def inputs(spec: Spec) -> dict[str, str]:
    """``{what: SHA-256 of its content}`` for every file the campaign's runs read besides
    the spec and the base scenario (see the module's docstring). A robot model or module
    that cannot be found is left out: its runs fail and say so."""
    from ..sim import robots
    from .task import spec_folders

    models: dict[str, None] = {}
    modules: dict[str, None] = {}
    for doc in _scenarios(spec):
        models.update(dict.fromkeys(_models(doc)))
        modules.update(dict.fromkeys(_modules(doc)))
    out: dict[str, str] = {}
    for name in models:
        try:
            path = robots.resolve(name, where="team.robot_model")
        except ScenarioError:
            continue
        out[f"robot {name}"] = _digest(path)
        mjcf = path
        if path.name.endswith(".toml"):
            try:
                mjcf = robots.load(path).mjcf
            except ScenarioError:
                continue
        for f in _mjcf_files(mjcf):
            shown = f.relative_to(mjcf.parent) if f.is_relative_to(mjcf.parent) else f
            out[f"robot {name}: {shown}"] = _digest(f)
    folders = spec_folders(spec)
    for module in modules:
        if module == "dftc_mujoco" or module.startswith("dftc_mujoco."):
            continue  # the package itself: campaign.json names its version
        found = _module_file(module, folders)
        if found is not None:
            out[f"plug-in {module}"] = _digest(found)
    return out
