"""Plug-in points for the six onboard blocks of the paper's Fig. 1.

A block is selected by a built-in name (``"paper"``) or by an import path
``"module:attribute"`` naming a class (or a factory) that returns a block
instance; keyword parameters come from ``[onboard.params.<block>]``. The
paper's blocks are :mod:`dftc_mujoco.blocks.paper`. Block classes are imported
where the run executes (CLI process, campaign worker, Ray worker), so a user's
module only has to be importable there: on ``sys.path``, or beside the
scenario file that names it.
"""

from __future__ import annotations

import importlib
import re
import sys
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from ..errors import ScenarioError

#: the six plug-in points, in the order a control period uses them
BLOCKS = ("observer", "controller", "supervisor", "fault_estimator", "thresholds", "decision")

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
    "decision": {"paper": "dftc_mujoco.blocks.paper:Decision"},
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
    names = ", ".join(repr(n) for n in BUILTIN[block])
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


def load_class(block: str, name: str, search: Sequence[Path] = (), where: str = "") -> Any:
    """The class (or factory) ``name`` selects for ``block``; ``search`` folders are tried
    after sys.path."""
    where = where or f"onboard.{block}"
    target = BUILTIN[block].get(name, name)
    module_name, _, attr = target.partition(":")
    module = _import(module_name, search, where)
    obj: Any = module
    for part in attr.split("."):
        if not hasattr(obj, part):
            raise ScenarioError(f"{where}: module {module_name!r} has no attribute {attr!r}")
        obj = getattr(obj, part)
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
