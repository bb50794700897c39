"""Plug-in points for the onboard blocks of the paper's Fig. 1 (six, and the detector).

A block is selected by a built-in name (``"paper"``) or by an import path
``"module:Class"`` naming a class derived from that block's class in
:mod:`dftc_mujoco.blocks.paper` (checked before use: any other callable, a function of
the standard library say, is refused in one line and never called); keyword
parameters come from ``[onboard.params.<block>]``. Block classes are imported where
the run executes (CLI process, campaign worker, Ray worker), so a user's module only
has to be importable there: on ``sys.path``, or beside the scenario file that names it.
Importing a module runs its code, as any plug-in does: a scenario that names a module
is as trusted as that module.
"""

from __future__ import annotations

import importlib
import re
import sys
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from ..errors import ScenarioError, raised_line

#: the plug-in points, in the order a control period uses them
BLOCKS = (
    "observer",
    "controller",
    "supervisor",
    "fault_estimator",
    "thresholds",
    "detector",
    "decision",
)

#: built-in names per block -> "module:attribute"
BUILTIN: dict[str, dict[str, str]] = {
    "observer": {"paper": "dftc_mujoco.blocks.paper:Observer"},
    "controller": {"paper": "dftc_mujoco.blocks.paper:Controller"},
    "supervisor": {"paper": "dftc_mujoco.blocks.paper:Supervisor"},
    "fault_estimator": {"paper": "dftc_mujoco.blocks.paper:FaultEstimator"},
    "thresholds": {
        "paper": "dftc_mujoco.blocks.paper:Thresholds",
        "block_row": "dftc_mujoco.onboard.thresholds.block_row:BlockRow",
        "drive": "dftc_mujoco.onboard.thresholds.drive:Drive",
        "l1": "dftc_mujoco.onboard.thresholds.l1:L1",
    },
    "decision": {
        "paper": "dftc_mujoco.blocks.paper:Decision",
        "none": "dftc_mujoco.onboard.decision:NoDecision",  # no detection, no isolation
    },
    "detector": {"paper": "dftc_mujoco.blocks.paper:Detector"},
}

_IMPORT_PATH = re.compile(r"^[A-Za-z_][\w]*(\.[A-Za-z_][\w]*)*:[A-Za-z_][\w]*(\.[A-Za-z_][\w]*)*$")


def check_name(block: str, name: Any) -> str | None:
    """Why ``name`` cannot select ``block`` (a message), or None when it is well formed.

    Only the form is checked here (a built-in name or ``module:attribute``);
    the import happens where the run executes (:func:`create`).
    """
    if not isinstance(name, str):
        return f"expected a string, got {type(name).__name__} {name!r}"
    if name in BUILTIN[block] or _IMPORT_PATH.match(name):
        return None
    if block == "thresholds" and name == "auto":  # resolved with the robots (assembly)
        return None
    words = [*BUILTIN[block], *(["auto"] if block == "thresholds" else [])]
    names = ", ".join(repr(n) for n in words)
    return f'expected a built-in name ({names}) or an import path "module:Class", got {name!r}'


def _import(module_name: str, search: Sequence[Path], where: str) -> Any:
    """Import ``module_name`` from sys.path, else from the folders ``search`` (in order)."""
    try:
        return importlib.import_module(module_name)
    except ModuleNotFoundError as exc:
        if exc.name is None or not module_name.startswith(exc.name):
            raise ScenarioError(f"{where}: importing {module_name!r} failed: {exc}") from None
        missing = exc
    except Exception as exc:  # the user's module failed while importing
        raise ScenarioError(
            f"{where}: importing {module_name!r} failed: {type(exc).__name__}: {exc}"
        ) from None
    top = module_name.split(".")[0]
    for folder in search:
        if not (Path(folder) / top).is_dir() and not (Path(folder) / f"{top}.py").is_file():
            continue
        sys.path.append(str(folder))  # a module beside the scenario (or campaign) file
        try:
            return importlib.import_module(module_name)
        except Exception as exc:
            raise ScenarioError(
                f"{where}: importing {module_name!r} from {folder} failed: "
                f"{type(exc).__name__}: {exc}"
            ) from None
        finally:
            sys.path.remove(str(folder))
    places = ", ".join(str(f) for f in search)
    raise ScenarioError(
        f"{where}: cannot import {module_name!r}: {missing} (searched sys.path"
        + (f" and {places})" if places else ")")
    ) from None


def base_class(block: str) -> type:
    """The class every ``block`` derives from (the paper's block of that plug-in point)."""
    from ..onboard.execution.team import PAPER_BLOCKS

    return PAPER_BLOCKS[block]


def not_a_block(block: str, obj: Any, name: str) -> str | None:
    """Why ``obj`` (what ``name`` selects) cannot fill ``block``, or None when it can:
    a class derived from :func:`base_class`, or an instance of one."""
    base = base_class(block)
    if (isinstance(obj, type) and issubclass(obj, base)) or isinstance(obj, base):
        return None
    if isinstance(obj, type):
        got = f"class {obj.__module__}.{obj.__qualname__}"
    elif callable(obj):
        where = f"{getattr(obj, '__module__', None) or '?'}.{getattr(obj, '__qualname__', '?')}"
        got = f"{type(obj).__name__} {where}"
    else:
        got = f"{type(obj).__name__} {obj!r:.60}"
    return (
        f"{name!r} is not a {block} block: expected a class derived from "
        f"dftc_mujoco.blocks.paper.{base.__name__}, got {got}"
    )


def load_class(block: str, name: str, search: Sequence[Path] = (), where: str = "") -> Any:
    """The block class ``name`` selects for ``block``; ``search`` folders are tried after
    sys.path. ScenarioError when it is not a class derived from :func:`base_class`."""
    if block not in BUILTIN:
        raise ScenarioError(f"unknown block {block!r}; expected one of {', '.join(BLOCKS)}")
    where = where or f"onboard.{block}"
    target = BUILTIN[block].get(name, name)
    module_name, _, attr = target.partition(":")
    module = _import(module_name, search, where)
    obj: Any = module
    for part in attr.split("."):
        if not hasattr(obj, part):
            raise ScenarioError(f"{where}: module {module_name!r} has no attribute {attr!r}")
        obj = getattr(obj, part)
    why = not_a_block(block, obj, name)
    if why:
        raise ScenarioError(f"{where}: {why}")
    return obj


def create(
    block: str,
    name: str,
    params: Mapping[str, Any] | None = None,
    search: Sequence[Path] = (),
    where: str = "",
) -> Any:
    """A new block instance: ``load_class(...)(**params)``; errors name the scenario key."""
    where = where or f"onboard.{block}"
    cls = load_class(block, name, search, where)
    try:
        return cls(**dict(params or {}))
    except TypeError as exc:
        raise ScenarioError(
            f"{where}: cannot create {name!r} with onboard.params.{block}: {exc}"
        ) from None
    except Exception as exc:  # the block's own check of its parameters (or a bug in it)
        raise ScenarioError(
            f"{where}: creating {name!r} with onboard.params.{block} raised {raised_line(exc)}"
        ) from exc
