"""The scenario: the validated whole (:class:`Scenario`), and loading it from a file, a
document or overrides."""

from __future__ import annotations

import contextlib
import contextvars
import copy
import dataclasses
import math
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..blocks import BLOCKS
from ..core.graph import Graph
from ..core.mission import CentroidPath, Formation, Mission
from ..errors import ScenarioError
from ..runtime.paths import SCENARIOS
from ..runtime.tomlcheck import Abort, Doc, _nested, _segments, describe, read_toml
from .crosscheck import cross_problems
from .parts import (
    Fault,
    Fdir,
    Gains,
    Network,
    Noise,
    Obstacle,
    Onboard,
    Physics,
    RadioFault,
    Supervision,
    Team,
)
from .readers import document
from .scale import scale_problem, scaled
from .writer import _dumps

# True while this module builds a Scenario from data it has just validated:
# Scenario.__post_init__ then skips its own validation (which parses the
# scenario's dict and builds a Scenario, so it would never end otherwise).
_TRUSTED: contextvars.ContextVar[bool] = contextvars.ContextVar("scenario_trusted", default=False)


@contextlib.contextmanager
def _trusted() -> Iterator[None]:
    token = _TRUSTED.set(True)
    try:
        yield
    finally:
        _TRUSTED.reset(token)


@dataclass(frozen=True, eq=False)
class Scenario:
    """A whole validated scenario.

    Every construction path validates: :func:`load`, :func:`load_scenario`,
    :func:`from_dict`, and direct construction (``Scenario(...)``,
    ``dataclasses.replace``), which checks :meth:`to_dict` exactly as a file
    is checked and raises :class:`ScenarioError` naming ``source``.
    """

    name: str
    description: str
    duration: float
    seed: int
    physics: Physics
    team: Team
    gains: Gains
    noise: Noise
    mission: Mission
    obstacles: tuple[Obstacle, ...]
    faults: tuple[Fault, ...]
    fdir: Fdir
    source: str = "<memory>"
    onboard: Onboard = field(default_factory=Onboard)
    supervisor: Supervision = field(default_factory=Supervision)
    network: Network = field(default_factory=Network)
    #: the ``mission.scale`` its document was read with (its lengths and times are already
    #: scaled; 1: none): what a suggested scale multiplies, not part of the document
    scale: float = field(default=1.0, compare=False, repr=False)

    def __post_init__(self) -> None:
        if not _TRUSTED.get():
            self._validate(self.source)

    def _validate(self, file: str) -> None:
        """Raise :class:`ScenarioError` (naming ``file``) unless this scenario is valid."""
        problems = _structure_problems(self, file)
        if problems:
            raise ScenarioError("\n".join(problems))
        _parse(self.to_dict(), file)

    @classmethod
    def from_dict(cls, data: dict[str, Any], source: str = "<memory>") -> Scenario:
        """Validate a parsed TOML document; the same as the module's :func:`from_dict`.

        Args:
            data: The document, as :func:`tomllib.loads` returns it.
            source: The name errors give for the document (a file path).

        Returns:
            The validated scenario.

        Raises:
            ScenarioError: Every problem found, one line each.
        """
        return from_dict(data, source)

    @property
    def directory(self) -> Path | None:
        """The folder of the scenario file, or None when ``source`` is not an existing file.

        Onboard blocks named by import path are also searched there.
        """
        path = Path(self.source)
        try:
            is_file = path.is_file()
        except (OSError, ValueError):
            return None
        return path.absolute().parent if is_file else None

    def to_dict(self) -> dict[str, Any]:
        """The scenario as a TOML-ready document (plain lists, numbers, strings, dicts).

        Robots are numbered from 1, as in files. Generated initial positions and
        graphs are written out as the resolved positions and ``[from, to]``
        edges (``team.graph_family`` keeps the family's name), so that
        :func:`from_dict` gives back the same numbers. ``noise.xi_bar`` is
        left out when None; every other field of every part is written.
        ``source`` is not part of the document.

        Returns:
            A new dict that :func:`from_dict` accepts.
        """
        team, mission = self.team, self.mission
        graph = team.graph
        edges = (
            [[_one_based(_plain(j)), _one_based(_plain(i))] for j, i in graph.edges]
            if isinstance(graph, Graph)
            else _plain(graph)
        )
        noise = _fields(self.noise)
        if noise.get("xi_bar") is None:
            del noise["xi_bar"]
        onboard = {b: _plain(getattr(self.onboard, b)) for b in BLOCKS}
        onboard["params"] = _plain(self.onboard.params)
        return {
            "name": _plain(self.name),
            "description": _plain(self.description),
            "duration": _plain(self.duration),
            "seed": _plain(self.seed),
            "physics": _fields(self.physics),
            "team": {
                "robots": _plain(team.robots),
                "robot_model": _plain(team.robot_model),
                "initial_positions": _plain(team.initial_positions),
                "graph": edges,
                "graph_family": _plain(team.graph_family),
            },
            "gains": {**_fields(self.gains), **({"G": "auto"} if self.gains.G is None else {})},
            "noise": noise,
            "mission": {
                "transient": _plain(mission.transient),
                "centroid": _fields(mission.centroid),
                "formation": _fields(mission.formation),
            },
            "obstacles": [_fields(o) for o in self.obstacles],
            "faults": [_fault(f) for f in self.faults]
            + [_radio_fault(f) for f in self.network.faults],
            "fdir": _fields(self.fdir),
            "supervisor": _fields(self.supervisor),
            "onboard": onboard,
            **({"network": _network(self.network)} if self.network != Network() else {}),
        }

    def to_toml(self) -> str:
        """The scenario as a TOML document (:meth:`to_dict` as text).

        Floats are written with ``repr``, so reading the text back gives the
        same numbers bit for bit.
        """
        return _dumps(self.to_dict())

    def with_overrides(
        self,
        *,
        seed: int | None = None,
        duration: float | None = None,
        robot_model: str | tuple[str, ...] | None = None,
        speed: float | None = None,
    ) -> Scenario:
        """A copy with CLI overrides applied and checked (``speed``: the centroid path's, as
        the path governor sets it: ``dftc_mujoco.core.mission.governed_speed``).

        A shorter ``duration`` drops the faults that would start after the new
        end (they cannot happen); :func:`dropped_faults` lists them. When it is
        not longer than ``mission.transient``, the transient becomes
        ``min(5, duration / 2)`` (a file's default), so that the error window is
        not empty.
        """
        where = f"{self.source} (command line)"
        changes: dict[str, Any] = {}
        if seed is not None:
            if seed < 0:
                raise ScenarioError(f"{where}: --seed: expected an integer >= 0, got {seed}")
            changes["seed"] = int(seed)
        if duration is not None:
            if not (duration > 0 and math.isfinite(duration)):
                raise ScenarioError(f"{where}: --duration: expected a number > 0, got {duration}")
            changes["duration"] = float(duration)
            changes["faults"] = tuple(f for f in self.faults if f.t < duration)
            if self.mission.transient >= duration:
                changes["mission"] = dataclasses.replace(
                    self.mission, transient=min(5.0, duration / 2)
                )
        if robot_model is not None:
            changes["team"] = dataclasses.replace(self.team, robot_model=robot_model)
        if speed is not None:
            mission = changes.get("mission", self.mission)
            centroid = dataclasses.replace(mission.centroid, speed=float(speed))
            changes["mission"] = dataclasses.replace(mission, centroid=centroid)
        if not changes:
            return self
        with _trusted():
            s = dataclasses.replace(self, **changes)
        s._validate(where)
        return s


def dropped_faults(original: Scenario, current: Scenario) -> list[Fault]:
    """Faults of ``original`` that ``current`` no longer has (cut by a shorter duration)."""
    kept = {id(f) for f in current.faults}
    return [f for f in original.faults if id(f) not in kept]


def _plain(v: Any) -> Any:
    """``v`` with numpy arrays and scalars, tuples and mappings made plain Python."""
    if isinstance(v, np.ndarray):
        return v.tolist()
    if isinstance(v, np.generic):
        return v.item()
    if isinstance(v, list | tuple):
        return [_plain(x) for x in v]
    if isinstance(v, Mapping):
        return {k: _plain(x) for k, x in v.items()}
    return v


def _fields(obj: Any) -> dict[str, Any]:
    return {f.name: _plain(getattr(obj, f.name)) for f in dataclasses.fields(obj)}


def _fault(f: Fault) -> dict[str, Any]:
    """A fault as its ``[[faults]]`` table (robots numbered from 1; only the keys its kind
    reads; no end: absent)."""
    d = {**_fields(f), "robot": _one_based(_plain(f.robot))}
    if not math.isfinite(f.end):
        del d["end"]
    if f.kind != "intermittent":
        del d["period"], d["duty"]
    if f.kind in ("bias", "stop"):
        return d  # value and time_constant (zeros for a stop)
    del d["time_constant"]
    if f.kind in ("intermittent", "stuck"):
        del d["value"]
    elif f.kind == "loss_of_effectiveness":
        d["value"] = _plain(float(f.value[0]))
    return d


def _radio_fault(f: RadioFault) -> dict[str, Any]:
    """A radio fault as its ``[[faults]]`` table (robots numbered from 1)."""
    d: dict[str, Any] = {"kind": f.kind, "t": _plain(f.t)}
    if f.kind == "link_down":
        d["link"] = [int(f.link[0]) + 1, int(f.link[1]) + 1]
    else:
        d["robot"] = int(f.robot) + 1
    if f.kind == "corrupt":
        d["value"] = _plain(f.value)
    return d


def _network(net: Network) -> dict[str, Any]:
    """The ``[network]`` table (radio faults go to ``[[faults]]``; absent keys: defaults)."""
    d: dict[str, Any] = {}
    if net.latency_max is not None:
        d["latency"] = {"mean": _plain(net.latency), "max": _plain(net.latency_max)}
    else:
        d["latency"] = _plain(net.latency)
    if net.rate is not None:
        d["rate"] = _plain(net.rate)
    d["loss"], d["loss_model"] = _plain(net.loss), net.loss_model
    if net.loss_model == "gilbert_elliott":
        d.update(p_bad=net.p_bad, p_good=net.p_good, loss_bad=net.loss_bad)
    if net.max_consecutive_losses is not None:
        d["max_consecutive_losses"] = int(net.max_consecutive_losses)
    if net.range is not None:
        d["range"] = _plain(net.range)
        d["range_hysteresis"] = _plain(net.range_hysteresis)
    links: dict[tuple[int, int], dict[str, Any]] = {}
    for items, name in ((net.link_loss, "loss"), (net.link_latency, "latency")):
        for (j, i), v in items:
            links.setdefault((j, i), {"link": [int(j) + 1, int(i) + 1]})[name] = _plain(v)
    if links:
        d["links"] = list(links.values())
    if net.sighting_tolerance != "auto":
        d["sighting_tolerance"] = _plain(net.sighting_tolerance)
    if net.sighting_range is not None:
        d["sighting_range"] = _plain(net.sighting_range)
    if net.connectivity_window is not None:
        d["connectivity_window"] = _plain(net.connectivity_window)
    return d


def _one_based(v: Any) -> Any:
    return v + 1 if isinstance(v, int) and not isinstance(v, bool) else v


def _structure_problems(s: Scenario, file: str) -> list[str]:
    """What a hand-built scenario has of the wrong type (a file cannot have these)."""
    problems = []

    def check(key: str, value: Any, cls: type) -> bool:
        if isinstance(value, cls):
            return True
        problems.append(f"{file}: {key}: expected a {cls.__name__}, got {type(value).__name__}")
        return False

    parts = {
        "physics": Physics,
        "team": Team,
        "gains": Gains,
        "noise": Noise,
        "mission": Mission,
    }
    for key, cls in parts.items():
        check(key, getattr(s, key), cls)
    for key, cls in (("obstacles", Obstacle), ("faults", Fault)):
        items = getattr(s, key)
        if not isinstance(items, tuple | list) or not all(isinstance(x, cls) for x in items):
            got = describe(list(items)) if isinstance(items, tuple | list) else type(items).__name__
            problems.append(f"{file}: {key}: expected a tuple of {cls.__name__}, got {got}")
    check("fdir", s.fdir, Fdir)
    check("onboard", s.onboard, Onboard)
    check("supervisor", s.supervisor, Supervision)
    check("network", s.network, Network)
    if isinstance(s.team, Team) and check("team.graph", s.team.graph, Graph):
        if s.team.graph.n != s.team.robots:
            problems.append(
                f"{file}: team.graph: expected a graph on team.robots = {s.team.robots} "
                f"robots, got one on {s.team.graph.n}"
            )
    if isinstance(s.mission, Mission):
        check("mission.centroid", s.mission.centroid, CentroidPath)
        check("mission.formation", s.mission.formation, Formation)
    return problems


def resolve(name_or_path: str | Path) -> Path:
    """The file for a scenario name (``scenarios/NAME.toml``) or path."""
    p = Path(name_or_path)
    if p.suffix == ".toml" or p.exists() or len(p.parts) > 1:
        if not p.is_file():
            raise ScenarioError(f"{p}: no such scenario file")
        return p
    candidate = SCENARIOS / f"{p}.toml"
    if not candidate.is_file():
        names = sorted(f.stem for f in SCENARIOS.glob("*.toml"))
        raise ScenarioError(
            f"{name_or_path}: no scenario of that name in {SCENARIOS} "
            f"(available: {', '.join(names) or 'none'}); give a name or a path to a .toml file"
        )
    return candidate


def load(name_or_path: str | Path) -> Scenario:
    """Load and validate a scenario by name or path."""
    return load_scenario(name_or_path)


def load_scenario(name_or_path: str | Path, overrides: Mapping[str, Any] | None = None) -> Scenario:
    """Load a scenario by name or path, apply dotted-key overrides, and validate it.

    :param name_or_path: A name (``scenarios/NAME.toml``) or a path to a ``.toml`` file.
    :param overrides: Values by dotted key, e.g. ``{"gains.ko": 3, "faults.1.t": 12.0}``
        (see :func:`apply_overrides`). An overridden ``duration`` acts as
        :meth:`Scenario.with_overrides` does: faults that would start after the
        new end are dropped and a ``mission.transient`` that is not shorter
        becomes ``min(5, duration / 2)``, unless those keys are overridden too.
    :returns: The validated scenario; its ``source`` is the file.
    :raises ScenarioError: Every problem found, one line each naming the file and the
        key; a problem with an overridden key names the file as ``FILE (override)``.
    """
    path = resolve(name_or_path)
    data = read_toml(path)
    keys: tuple[str, ...] = ()
    if overrides:
        data = apply_overrides(data, overrides, where=f"{path} (override)")
        keys = tuple(overrides)
        _fit_to_duration(data, keys)
    return _parse(data, str(path), keys)


def _fit_to_duration(data: dict[str, Any], overridden: tuple[str, ...]) -> None:
    """An overridden duration acts as ``--duration``: drop the faults after the new end
    and shorten a transient that is not shorter (unless those keys are overridden too)."""
    duration = data.get("duration")
    if (
        "duration" not in overridden
        or isinstance(duration, bool)
        or not isinstance(duration, int | float)
        or not duration > 0
    ):
        return

    def touched(key: str) -> bool:
        return any(_nested(_segments(key), _segments(k)) for k in overridden)

    def number(v: Any) -> bool:
        return isinstance(v, int | float) and not isinstance(v, bool)

    faults = data.get("faults")
    if isinstance(faults, list) and not touched("faults"):
        data["faults"] = [
            f
            for f in faults
            if not (isinstance(f, dict) and number(f.get("t")) and f["t"] >= duration)
        ]
    mission = data.get("mission")
    if (
        isinstance(mission, dict)
        and not touched("mission.transient")
        and number(mission.get("transient"))
        and mission["transient"] >= duration
    ):
        mission["transient"] = min(5.0, duration / 2)


def apply_overrides(
    data: dict[str, Any], overrides: Mapping[str, Any], where: str
) -> dict[str, Any]:
    """A deep copy of a parsed TOML document with values set by dotted key.

    ``{"gains.ko": 3, "onboard.thresholds": "paper"}`` sets ``ko`` in ``[gains]``
    and ``thresholds`` in ``[onboard]``; missing tables are created. Elements of
    arrays (of tables) are addressed by 1-based index: ``"faults.1.t"``. A value
    of None removes the key. Tuples and numpy values become lists and numbers.
    The result is not validated (:func:`from_dict` does that).

    Args:
        data: The document, as :func:`tomllib.loads` returns it (not modified).
        overrides: Values by dotted key.
        where: What errors name as the file, e.g. ``"paper_case.toml (override)"``.

    Returns:
        The new document.

    Raises:
        ScenarioError: A key is malformed, crosses a value that is not a table
            (``"duration.x"``) or indexes past an array's end; every such key is
            reported, one line each.
    """
    if not isinstance(overrides, Mapping):  # an AttributeError ('items') before
        raise TypeError(
            f"overrides: expected a mapping of dotted keys to values, such as "
            f'{{"gains.ko": 3}}, got {type(overrides).__name__}'
        )
    out = copy.deepcopy(data)
    problems = []
    for key, value in overrides.items():
        problem = _override(out, key, value)
        if problem:
            problems.append(f"{where}: {key}: {problem}")
    if problems:
        raise ScenarioError("\n".join(problems))
    return out


def _override(data: dict[str, Any], key: Any, value: Any) -> str | None:
    """Set one dotted key in ``data``; what is wrong, or None."""
    parts = key.split(".") if isinstance(key, str) else []
    if not parts or not all(parts):
        return f'expected a dotted key such as "gains.ko", got {key!r}'
    if any("[" in p or "]" in p for p in parts):  # faults[0].t: it was "unknown key faults[0]"
        return (
            "expected a dotted key, an array's items numbered from 1 after a dot (e.g. "
            f'"faults.1.t"), got {key!r}'
        )
    node: Any = data
    for depth, part in enumerate(parts):
        last = depth == len(parts) - 1
        here = ".".join(parts[:depth]) or "the document"
        if isinstance(node, dict):
            if last:
                if value is None:
                    node.pop(part, None)
                else:
                    node[part] = _plain(value)
                return None
            if part not in node:
                node[part] = {}
            node = node[part]
        elif isinstance(node, list):
            if not (part.isdigit() and 1 <= int(part) <= len(node)):
                return (
                    f"expected an index 1..{len(node)} into the array {here}, got {part!r}"
                    if node
                    else f"expected an index into the array {here}, but it is empty"
                )
            if last:
                if value is None:
                    return f"cannot remove element {part} of the array {here}"
                node[int(part) - 1] = _plain(value)
                return None
            node = node[int(part) - 1]
        else:
            return f"expected {here} to be a table, got {describe(node)}"
    return None  # pragma: no cover (the loop always returns)


def from_dict(data: dict[str, Any], source: str = "<memory>") -> Scenario:
    """Validate a parsed TOML document (as :func:`tomllib.loads` returns it).

    Args:
        data: The document.
        source: The name errors give for the document (a file path).

    Returns:
        The validated scenario.

    Raises:
        ScenarioError: Every problem found, one line each (``source: key: what
            was expected, got ...``), in file order.
    """
    return _parse(data, source)


def _parse(data: Any, source: str, overridden: tuple[str, ...] = ()) -> Scenario:
    problem, k = None, 1.0
    if isinstance(data, dict):  # mission.scale: the document's lengths and times, scaled
        data = _plain(data)  # a document built in Python may hold numpy values and tuples
        k, problem = scale_problem(data)
        data = scaled(data, k)
    doc = Doc(source, data, overridden)
    if problem:
        doc.record("mission.scale", problem)
    try:
        fields = document(doc, data)
    except Abort:
        fields = None
    if fields is not None:
        cross_problems(doc, fields)
    doc.raise_problems()
    assert fields is not None  # every skip follows a recorded problem
    with _trusted():
        return Scenario(**fields, scale=k if isinstance(data, dict) else 1.0)
