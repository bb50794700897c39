"""Scenarios: TOML files turned into frozen, validated dataclasses.

A scenario is loaded by name (``scenarios/NAME.toml``) or by path, optionally
with dotted-key overrides (:func:`load_scenario`). Every problem is reported
in one :class:`~dftc_mujoco.errors.ScenarioError`, one line per problem in
file order, each naming the file, the key and what was expected. Robots are
numbered from 1 in the file (as in the paper) and from 0 inside the code.

A :class:`Scenario` built in code (``Scenario(...)``, ``dataclasses.replace``)
is validated exactly as a file is: :meth:`Scenario.to_dict` turns it back into
a TOML document, which goes through the same checks. :meth:`Scenario.to_toml`
writes that document as text.
"""

from __future__ import annotations

import contextlib
import contextvars
import copy
import dataclasses
import datetime
import keyword
import math
import re
import tomllib
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NoReturn, TypeVar, cast

import numpy as np

from .blocks import BLOCKS, check_name
from .errors import ScenarioError
from .graph import Graph
from .mission import CentroidPath, Formation, Mission, formation_offsets
from .paths import SCENARIOS

__all__ = [
    "N_DIM",
    "SCENARIOS",
    "CentroidPath",
    "Fault",
    "Fdir",
    "Formation",
    "Gains",
    "Mission",
    "Noise",
    "Obstacle",
    "Onboard",
    "Physics",
    "Scenario",
    "Supervision",
    "Team",
    "apply_overrides",
    "dropped_faults",
    "from_dict",
    "load",
    "load_scenario",
    "resolve",
]

N_DIM = 2  # planar robots: n = 2 in the paper's notation
_MISSING = object()
_T = TypeVar("_T")

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


def _ro(a: Any) -> np.ndarray:
    arr = np.array(a, dtype=float)
    arr.setflags(write=False)
    return arr


class _ReadOnlyMap(Mapping[str, Any]):
    """A read-only (and picklable) mapping."""

    __slots__ = ("_data",)

    def __init__(self, data: Mapping[str, Any] | None = None):
        self._data = dict(data or {})

    def __getitem__(self, key: str) -> Any:
        return self._data[key]

    def __iter__(self) -> Iterator[str]:
        return iter(self._data)

    def __len__(self) -> int:
        return len(self._data)

    def __repr__(self) -> str:
        return repr(self._data)

    def __reduce__(self) -> tuple[Any, ...]:
        return (_ReadOnlyMap, (self._data,))

    def __hash__(self) -> int:  # equal mappings have equal keys (values may be lists)
        return hash(frozenset(self._data))


@dataclass(frozen=True)
class Physics:
    """Integration settings: MuJoCo timestep, control period and log rate."""

    timestep: float = 0.002
    control_period: float = 0.01
    log_rate: float = 50.0
    robot_contacts: bool = True
    # rate of the N × N fields (estimates, residuals, thresholds) [Hz], or "auto": the
    # log rate while they fit in MATRIX_LOG_BUDGET bytes, less for large teams
    matrix_log_rate: float | str = "auto"

    @property
    def substeps(self) -> int:
        """MuJoCo steps per control period."""
        return round(self.control_period / self.timestep)


@dataclass(frozen=True, eq=False)
class Team:
    """The robots, their model, initial positions and communication graph."""

    robots: int
    robot_model: str
    initial_positions: np.ndarray  # (N, 2)
    graph: Graph
    graph_family: str = "explicit"  # or ring_chords, random, knn when generated


@dataclass(frozen=True, eq=False)
class Gains:
    """Controller, observer, fault-estimator and avoidance gains (eqs. 15, 19, 29, 30, 18)."""

    kc: float
    ko: float
    K: np.ndarray  # (2, 2), symmetric positive definite
    G: np.ndarray | None  # (2, 2), symmetric positive definite; None ("auto"): the robot's
    theta: float


@dataclass(frozen=True)
class Noise:
    """Bounds of measurement noise (eq. 4) and disturbance (eq. 2)."""

    eta_bar: float
    xi_bar: float | None  # None: the robot model's measured mismatch
    xi_time_constant: float = 0.5
    at_bound: bool = False  # draw η and ξ with norms exactly at η̄ and ξ̄


@dataclass(frozen=True, eq=False)
class Obstacle:
    """A vertical cylinder; ``safe_distance`` is d of eq. 17 (robot centre to cylinder axis)."""

    position: np.ndarray  # (2,)
    radius: float
    safe_distance: float
    activation_distance: float
    height: float = 0.3


@dataclass(frozen=True, eq=False)
class Fault:
    """An actuator fault on ``robot`` (0-based) starting at ``t``.

    ``value`` and ``time_constant`` describe a bias; a stop fault keeps them at
    zero (a file may give them for a stop fault only as zeros).
    """

    robot: int
    kind: str  # "bias" or "stop"
    t: float
    value: np.ndarray = field(default_factory=lambda: _ro([0.0, 0.0]))
    time_constant: float = 0.0


@dataclass(frozen=True)
class Fdir:
    """Fault detection, isolation and recovery settings (eqs. 39-43).

    ``enabled = false`` runs the nominal DFTC only (no compensation, no
    decisions), to compare against.
    """

    detection_window: float = 0.2
    dt_d_max: float | str = 5.0  # Δt_d,max [s], or "auto": from the analysis (eq. 46)
    # ε̄ [m], or "auto": derived from the start positions and the planned slots (premises.py)
    initial_error_bound: float | str = "auto"
    replan_time: float = 4.0
    excluded_safe_distance: float = 0.35
    excluded_activation_distance: float = 0.45
    phi_low_pass: float = 0.0
    enabled: bool = True
    compensate: bool = True  # false: φ̂ is estimated and logged but not applied
    isolation: str = "pairwise"  # "exclusive": eq. 39's 2nd clause now; "exclusive_history": ever
    reference_fault: float = 0.0  # [m/s] the fault Δt_d,max = "auto" is sized for (0: path speed)
    # the input that enters y_m, Δu and the fault estimator: "applied" (the nominal input
    # after the robot's own command limits, Remark 4.1) or "nominal" (as computed, eq. 8)
    input: str = "applied"
    # τ [s] of the first-order drive lag each robot models (onboard/applied.py), or "robot":
    # the robot file's calibrated [calibration] lag (0 when it has none: ẋ = u)
    drive_lag: float | str = "robot"
    # a_max [m/s²] each robot holds its nominal input's change to (onboard/applied.py), or
    # "robot": the robot file's calibrated [calibration] accel (none when it has none); 0: none
    drive_accel: float | str = "robot"
    # how many robots may be faulty at once, or "auto": ⌊(N − 1)/2⌋ (onboard/recovery.py)
    max_faults: int | str = "auto"
    self_exclusion: bool = False  # a robot's own flag counts towards its exclusion (eq. 43)
    postpone_on_contact: bool = True  # a bumper contact postpones the exclusion instant t_r
    excluded_relay: bool = False  # an excluded robot keeps relaying its neighbours' messages


@dataclass(frozen=True)
class Supervision:
    """The supervisor's reactive behaviours beside the cylinders (the ``[supervisor]`` table).

    ``avoid_teammates``: each robot avoids the teammates its range sensor sees, in the null
    space like an obstacle (eqs. 17-18), so the residuals are unaffected; false keeps the
    paper's exact behaviour. ``teammate_distance``: the safe distance between two robots'
    control points [m], or "auto": twice the robot's footprint plus 2 cm.
    """

    avoid_teammates: bool = True
    teammate_distance: float | str = "auto"


@dataclass(frozen=True)
class Onboard:
    """The onboard blocks of the paper's Fig. 1 (the ``[onboard]`` table).

    Each block is ``"paper"`` (the built-in implementation) or an import path
    ``"module:Class"`` (see :mod:`dftc_mujoco.blocks`). ``params`` maps a block
    name to the keyword arguments its class is created with
    (``[onboard.params.<block>]``); both levels are read-only.
    """

    observer: str = "paper"
    controller: str = "paper"
    supervisor: str = "paper"
    fault_estimator: str = "paper"
    thresholds: str = "paper"
    decision: str = "paper"
    params: Mapping[str, Mapping[str, Any]] = field(default_factory=_ReadOnlyMap)

    def __post_init__(self) -> None:
        if isinstance(self.params, Mapping):  # anything else is reported by validation
            frozen = {
                block: _ReadOnlyMap(copy.deepcopy(dict(kw))) if isinstance(kw, Mapping) else kw
                for block, kw in self.params.items()
            }
            object.__setattr__(self, "params", _ReadOnlyMap(frozen))


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
            "faults": [{**_fields(f), "robot": _one_based(_plain(f.robot))} for f in self.faults],
            "fdir": _fields(self.fdir),
            "supervisor": _fields(self.supervisor),
            "onboard": onboard,
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
        robot_model: str | None = None,
    ) -> Scenario:
        """A copy with CLI overrides applied and checked.

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
            got = (
                _describe(list(items)) if isinstance(items, tuple | list) else type(items).__name__
            )
            problems.append(f"{file}: {key}: expected a tuple of {cls.__name__}, got {got}")
    check("fdir", s.fdir, Fdir)
    check("onboard", s.onboard, Onboard)
    check("supervisor", s.supervisor, Supervision)
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


# --------------------------------------------------------------------------- reading


class _Abort(Exception):
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


class _Doc:
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
        except _Abort:
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


class _Table:
    """A TOML table read key by key; unread keys are reported as unknown.

    Without a ``doc`` the first problem raises :class:`ScenarioError`. With one,
    problems are recorded there: a reader whose key is wrong returns its
    default (or a placeholder) and the key is marked failed, so that the
    checks which need it can be skipped (:meth:`ok`).
    """

    def __init__(self, file: str, data: Any, path: str, doc: _Doc | None = None):
        self.file = file
        self.path = path
        self.doc = doc
        self.data = data if isinstance(data, dict) else {}
        self.used: set[str] = set()
        if not isinstance(data, dict):
            self.fail("", f"expected a table, got {_describe(data)}")

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
        raise _Abort(name)

    def ok(self, *names: str) -> bool:
        """True when none of these keys failed."""
        return self.doc is None or self.doc.ok(*(self.key(n) for n in names))

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
                self.fail(name, f"expected a number, got {_describe(v)}")
            v = float(v)
            if not math.isfinite(v):
                self.fail(name, f"expected a finite number, got {v}")
            if low is not None and (v <= low if strict_low else v < low):
                self.fail(
                    name, f"expected a number {'>' if strict_low else '>='} {low:g}, got {v:g}"
                )
            if high is not None and v > high:
                self.fail(name, f"expected a number <= {high:g}, got {v:g}")
            return v
        except _Abort:
            return 1.0 if default is _MISSING else float(default)

    def integer(self, name: str, default: Any = _MISSING, *, low: int | None = None) -> int:
        try:
            v = self.raw(name, default)
            if isinstance(v, bool) or not isinstance(v, int):
                self.fail(name, f"expected an integer, got {_describe(v)}")
            if low is not None and v < low:
                self.fail(name, f"expected an integer >= {low}, got {v}")
            return int(v)
        except _Abort:
            return (low or 0) if default is _MISSING else int(default)

    def string(self, name: str, default: Any = _MISSING, *, choices: tuple[str, ...] = ()) -> str:
        try:
            v = self.raw(name, default)
            if not isinstance(v, str):
                self.fail(name, f"expected a string, got {_describe(v)}")
            if choices and v not in choices:
                self.fail(name, f"expected one of {', '.join(map(repr, choices))}, got {v!r}")
            return v
        except _Abort:
            return "" if default is _MISSING else default

    def boolean(self, name: str, default: Any = _MISSING) -> bool:
        try:
            v = self.raw(name, default)
            if not isinstance(v, bool):
                self.fail(name, f"expected true or false, got {_describe(v)}")
            return v
        except _Abort:
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
                self.fail(name, f"expected {want}, got {_describe(v)}")
            if not np.all(np.isfinite(arr)):
                self.fail(name, f"expected finite numbers, got {v!r}")
            return _ro(arr)
        except _Abort:
            if default is not _MISSING:
                return _ro(default)
            return _ro(np.zeros([1 if s is None else s for s in shape]))

    def gain_matrix(self, name: str, auto: bool = False) -> np.ndarray:
        """A scalar (meaning scalar x I) or a symmetric positive definite 2x2 matrix
        (``auto``: the word "auto" is also accepted, by the caller)."""
        what = "a positive number" + (', "auto"' if auto else "") + " or a 2x2 matrix"
        try:
            v = self.raw(name)
            if isinstance(v, int | float) and not isinstance(v, bool):
                if not v > 0:
                    self.fail(name, f"expected {what}, got {v}")
                return _ro(float(v) * np.eye(N_DIM))
            m = _numeric_array(v)
            if m is None or m.shape != (N_DIM, N_DIM):
                self.fail(name, f"expected {what}, got {_describe(v)}")
            if (
                not np.all(np.isfinite(m))
                or not np.allclose(m, m.T)
                or np.linalg.eigvalsh(m).min() <= 0
            ):
                self.fail(name, f"expected a symmetric positive definite matrix, got {v!r}")
            return _ro(m)
        except _Abort:
            return _ro(np.eye(N_DIM))

    def table(self, name: str, default: Any = _MISSING) -> _Table:
        return _Table(self.file, self.raw(name, default), self.key(name), self.doc)

    def tables(self, name: str) -> list[_Table]:
        v = self.raw(name, [])
        if not isinstance(v, list) or not all(isinstance(x, dict) for x in v):
            self.fail(name, f"expected an array of tables ([[{name}]]), got {_describe(v)}")
        return [
            _Table(self.file, x, f"{self.key(name)}[{k + 1}]", self.doc) for k, x in enumerate(v)
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


def _describe(v: Any) -> str:
    if isinstance(v, dict):
        return "a table"
    if isinstance(v, list):
        return f"{v!r}" if len(repr(v)) < 60 else f"a list of {len(v)} items"
    return f"{type(v).__name__} {v!r}"


# --------------------------------------------------------------------------- loading


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


def _read(path: Path) -> dict[str, Any]:
    try:
        with open(path, "rb") as fh:
            return tomllib.load(fh)
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(f"{path}: not valid TOML: {exc}") from None
    except UnicodeDecodeError as exc:
        raise ScenarioError(
            f"{path}: not UTF-8 text (byte 0x{exc.object[exc.start]:02x} at offset "
            f"{exc.start}); TOML files must be UTF-8"
        ) from None
    except OSError as exc:
        raise ScenarioError(f"{path}: cannot read: {exc.strerror}") from None


def load(name_or_path: str | Path) -> Scenario:
    """Load and validate a scenario by name or path."""
    return load_scenario(name_or_path)


def load_scenario(name_or_path: str | Path, overrides: Mapping[str, Any] | None = None) -> Scenario:
    """Load a scenario by name or path, apply dotted-key overrides, and validate it.

    Args:
        name_or_path: A name (``scenarios/NAME.toml``) or a path to a ``.toml`` file.
        overrides: Values by dotted key, e.g. ``{"gains.ko": 3, "faults.1.t": 12.0}``
            (see :func:`apply_overrides`). An overridden ``duration`` acts as
            :meth:`Scenario.with_overrides` does: faults that would start after the
            new end are dropped and a ``mission.transient`` that is not shorter
            becomes ``min(5, duration / 2)``, unless those keys are overridden too.

    Returns:
        The validated scenario; its ``source`` is the file.

    Raises:
        ScenarioError: Every problem found, one line each naming the file and the
            key; a problem with an overridden key names the file as
            ``FILE (override)``.
    """
    path = resolve(name_or_path)
    data = _read(path)
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
            return f"expected {here} to be a table, got {_describe(node)}"
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
    doc = _Doc(source, data, overridden)
    try:
        scenario = _document(doc, data)
    except _Abort:
        scenario = None
    doc.raise_problems()
    assert scenario is not None  # every skip follows a recorded problem
    return scenario


NAME_PATTERN = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,99}$")


def name_problem(name: str) -> str | None:
    """Why ``name`` cannot name an output folder (it becomes ``renders/<name>``), or None."""
    if NAME_PATTERN.match(name) and ".." not in name:
        return None
    return (
        "expected a plain name (letters, digits, '_', '-', '.'; no path separators or '..', "
        f"at most 100 characters): it names the output folder renders/<name>, got {name!r}"
    )


def _document(doc: _Doc, data: Any) -> Scenario | None:
    top = _Table(doc.file, data, "", doc)
    name = top.string("name")
    problem = name_problem(name) if top.ok("name") else None
    if problem:
        top.report("name", problem)
    description = top.string("description", "")
    duration = top.number("duration", low=0.0)
    seed = top.integer("seed", 0, low=0)
    known_duration = duration if top.ok("duration") else None

    physics = doc.guard(lambda: _physics(top.table("physics", {})))
    mission = doc.guard(lambda: _mission(top.table("mission"), known_duration))
    team = doc.guard(lambda: _team(top.table("team"), mission, seed))
    gains = doc.guard(lambda: _gains(top.table("gains")))
    noise = doc.guard(lambda: _noise(top.table("noise")))
    obstacles = doc.guard(lambda: tuple(doc.guard(_obstacle, t) for t in top.tables("obstacles")))
    robots = team.robots if team is not None and doc.ok("team.robots") else None
    faults = doc.guard(
        lambda: tuple(doc.guard(_fault, t, robots, known_duration) for t in top.tables("faults"))
    )
    fdir = doc.guard(lambda: _fdir(top.table("fdir", {})))
    onboard = doc.guard(lambda: _onboard(top.table("onboard", {})))
    supervision = doc.guard(lambda: _supervision(top.table("supervisor", {})))
    top.finish()
    # Forward Euler on d/dt ŷ = k_o r is stable when every eigenvalue z of
    # k_o (L + Πₖ) satisfies |1 − dt z| < 1; Gershgorin's discs guarantee it
    # when k_o dt (2 d_max + 1) < 2.
    if (
        gains is not None
        and physics is not None
        and team is not None
        and team.graph is not None
        and doc.ok("gains.ko", "physics.control_period")
    ):
        step_gain = gains.ko * physics.control_period * (2 * team.graph.in_degree().max() + 1)
        if step_gain >= 2:
            doc.record(
                "gains.ko",
                "the observer update is unstable at this control period: "
                f"ko * control_period * (2 * max in-degree + 1) = {step_gain:g}, expected < 2; "
                "lower ko or physics.control_period",
            )
    if doc.problems:
        return None
    # every reader returned its value where it recorded no problem
    assert physics is not None and team is not None and gains is not None
    assert noise is not None and mission is not None and fdir is not None
    assert onboard is not None and supervision is not None
    assert obstacles is not None and faults is not None
    with _trusted():
        return Scenario(
            name,
            description,
            duration,
            seed,
            physics,
            team,
            gains,
            noise,
            mission,
            cast(tuple[Obstacle, ...], obstacles),
            cast(tuple[Fault, ...], faults),
            fdir,
            doc.file,
            onboard,
            supervision,
        )


def _supervision(t: _Table) -> Supervision:
    distance = _number_or_word(t, "teammate_distance", "auto", "a distance in m")
    s = Supervision(t.boolean("avoid_teammates", True), distance)
    t.finish()
    return s


def _physics(t: _Table) -> Physics:
    timestep = t.number("timestep", 0.002, low=0.0, high=0.1)
    period = t.number("control_period", 0.01, low=0.0, high=1.0)
    ratio = period / timestep
    if t.ok("timestep", "control_period") and (
        ratio < 1 - 1e-9 or abs(ratio - round(ratio)) > 1e-6
    ):
        t.report(
            "control_period",
            f"expected a whole multiple of timestep = {timestep:g}, got {period:g}",
        )
    log_rate = t.number("log_rate", 50.0, low=0.0)
    if t.ok("log_rate", "control_period") and log_rate > 1.0 / period + 1e-9:
        t.report(
            "log_rate", f"expected at most the control rate {1.0 / period:g} Hz, got {log_rate:g}"
        )
    contacts = t.boolean("robot_contacts", True)
    raw = t.data.get("matrix_log_rate", "auto")
    matrix_rate: float | str = "auto"
    if isinstance(raw, str):
        t.raw("matrix_log_rate", "auto")
        if raw != "auto":
            t.report("matrix_log_rate", f'expected a rate in Hz or "auto", got {raw!r}')
    else:
        matrix_rate = t.number("matrix_log_rate", 50.0, low=0.0)
        if t.ok("matrix_log_rate", "log_rate") and matrix_rate > log_rate + 1e-9:
            t.report(
                "matrix_log_rate",
                f"expected at most log_rate = {log_rate:g} Hz, got {matrix_rate:g}",
            )
    t.finish()
    return Physics(timestep, period, log_rate, contacts, matrix_rate)


_FAMILIES = ("explicit", "ring_chords", "random", "knn", "line")


def _team(t: _Table, mission: Mission | None, seed: int) -> Team:
    """The team; its graph is None when a problem (recorded) left it unknown."""
    assert t.doc is not None
    n = t.integer("robots", low=2)
    known_n = n if t.ok("robots") else None
    model = t.string("robot_model", "disk")
    x0 = t.doc.guard(_initial_positions, t, known_n, mission, seed)
    graph, family = t.doc.guard(_graph, t, known_n, x0, seed) or (None, None)
    if "graph_family" in t.data:
        given = t.string("graph_family", choices=_FAMILIES)
        if family not in (None, "explicit") and t.ok("graph_family") and given != family:
            t.report(
                "graph_family",
                f"expected {family!r} (the family of team.graph) or no graph_family, got {given!r}",
            )
        family = given
    t.finish()
    if x0 is None:
        x0 = _ro(np.zeros((max(n, 1), N_DIM)))
    return Team(n, model, x0, graph, family or "explicit")  # type: ignore[arg-type]


def _initial_positions(
    t: _Table, n: int | None, mission: Mission | None, seed: int
) -> np.ndarray | None:
    """A list of N [x, y], or a generated layout: {layout = "formation", jitter = m} (the
    planned slots at t = 0), {layout = "random", spread = m, spacing = m} (uniform in a square
    of half-width ``spread`` around the path's start, points ``spacing`` apart) or
    {layout = "circle", radius = m} (on a circle around the start, in a shuffled order;
    radius 0: the formation's)."""
    assert t.doc is not None
    raw = t.raw("initial_positions")
    if not isinstance(raw, dict):
        pairs = f"a list of {n} [x, y] pairs (team.robots = {n})" if n else "a list of [x, y] pairs"
        x0 = t.array(
            "initial_positions",
            (n, N_DIM),
            what=f'{pairs}, or a table {{layout = "formation" | "random" | "circle", ...}}',
        )
        return x0 if t.ok("initial_positions") else None
    lay = t.table("initial_positions")
    layout = lay.string("layout", choices=("formation", "random", "circle"))
    jitter = lay.number("jitter", 0.0, low=0.0, strict_low=False)
    spread = lay.number("spread", 5.0, low=0.0)  # random: half-width of the square [m]
    spacing = lay.number("spacing", 0.5, low=0.0, strict_low=False)  # random: least gap [m]
    radius = lay.number("radius", 0.0, low=0.0, strict_low=False)  # circle: 0 = formation's
    lay.finish()
    if (
        n is None
        or mission is None
        or not lay.ok("layout", "jitter", "spread", "spacing", "radius")
        or not t.doc.ok("mission.centroid.waypoints", "mission.formation")
    ):
        return None
    start = np.asarray(mission.centroid.waypoints[0])
    rng = np.random.default_rng([seed, 7])
    if layout == "random":  # uniform in a square around the path's start, points apart
        pts: list[np.ndarray] = []
        for _ in range(2000 * n):
            p = start + rng.uniform(-spread, spread, 2)
            if all(np.hypot(*(p - q)) >= spacing for q in pts):
                pts.append(p)
                if len(pts) == n:
                    return _ro(np.array(pts))
        t.report(
            "initial_positions",
            f"cannot place {n} robots {spacing:g} m apart within ±{spread:g} m: raise spread "
            "or lower spacing",
        )
        return None
    offsets = formation_offsets(mission.formation, n)
    if layout == "circle":  # on a circle around the start, in a shuffled order: each robot
        # starts up to a diameter away from its own slot
        r = radius or float(np.linalg.norm(offsets, axis=1).max())
        ang = 2 * np.pi * rng.permutation(n) / n
        return _ro(start + r * np.c_[np.cos(ang), np.sin(ang)])
    pts_ = start + offsets + rng.uniform(-jitter, jitter, (n, 2))
    return _ro(pts_)


def _graph(
    t: _Table, n: int | None, x0: np.ndarray | None, seed: int
) -> tuple[Graph | None, str | None]:
    """The team's graph and its family ("explicit" for an edge list)."""
    raw = t.raw("graph")
    if isinstance(raw, dict):
        graph, family = _generated_graph(t.table("graph"), n, x0, seed)
    else:
        graph, family = _edge_list(t, raw, n), "explicit"
    if graph is not None and not graph.is_strongly_connected():
        t.report(
            "graph",
            "expected a strongly connected graph (a directed path from every "
            "robot to every other); the observer cannot converge otherwise",
        )
    return graph, family


def _generated_graph(
    g: _Table, n: int | None, x0: np.ndarray | None, seed: int
) -> tuple[Graph | None, str | None]:
    """{family = "ring_chords", chords = [...]}, {family = "random", in_degree = d},
    {family = "knn", k = k} or {family = "line"} (i ⇄ i + 1: every inner robot a cut)."""
    from .graph import k_nearest, line_with_back_links, random_strongly_connected, ring_with_chords

    family = g.string("family", choices=("ring_chords", "random", "knn", "line"))
    if not g.ok("family"):
        return None, None
    graph: Graph | None = None
    if family == "ring_chords":
        chords = g.raw("chords", [])
        top = n - 1 if n is not None else math.inf
        if not isinstance(chords, list) or not all(
            isinstance(c, int) and not isinstance(c, bool) and 1 <= c <= top for c in chords
        ):
            high = n - 1 if n is not None else "N - 1"
            g.report("chords", f"expected a list of integers 1..{high}, got {_describe(chords)}")
        elif n is not None:
            graph = ring_with_chords(n, tuple(chords))
    elif family == "random":
        d = g.integer("in_degree", low=1)
        if n is not None and g.ok("in_degree"):
            graph = random_strongly_connected(n, d, np.random.default_rng([seed, 11]))
    elif family == "line":
        if n is not None:
            graph = line_with_back_links(n)
    else:
        k = g.integer("k", low=1)
        if x0 is not None and g.ok("k"):
            graph = k_nearest(np.asarray(x0), k)
    g.finish()
    return graph, family


def _edge_list(t: _Table, raw_edges: Any, n: int | None) -> Graph | None:
    if not isinstance(raw_edges, list) or not raw_edges:
        t.fail(
            "graph",
            f"expected a non-empty list of [from, to] robot pairs or a table "
            f"{{family = ...}}, got {_describe(raw_edges)}",
        )
    edges: list[tuple[int, int]] = []
    seen: set[tuple[int, int]] = set()
    bad = False
    for k, e in enumerate(raw_edges):
        key = f"graph[{k + 1}]"
        if (
            not isinstance(e, list)
            or len(e) != 2
            or not all(isinstance(v, int) and not isinstance(v, bool) for v in e)
        ):
            t.report(key, f"expected a [from, to] pair of robot numbers, got {_describe(e)}")
            bad = True
            continue
        a, b = e
        out = [v for v in (a, b) if not 1 <= v <= (n if n is not None else math.inf)]
        if out:
            t.report(key, f"robot {out[0]} out of range: robots are numbered 1..{n}")
        elif a == b:
            t.report(key, f"edge [{a}, {b}] goes from a robot to itself")
        elif (a - 1, b - 1) in seen:
            t.report(key, f"edge [{a}, {b}] appears twice")
        else:
            seen.add((a - 1, b - 1))
            edges.append((a - 1, b - 1))
            continue
        bad = True
    if bad or n is None:
        return None
    return Graph(n, tuple(edges))


def _gains(t: _Table) -> Gains:
    g = Gains(
        kc=t.number("kc", low=0.0),
        ko=t.number("ko", low=0.0),
        K=t.gain_matrix("K"),
        G=None if t.raw("G", None) == "auto" else t.gain_matrix("G", auto=True),
        theta=t.number("theta", 2.0, low=0.0),
    )
    t.finish()
    return g


def _noise(t: _Table) -> Noise:
    n = Noise(
        eta_bar=t.number("eta_bar", low=0.0, strict_low=False),
        xi_bar=None
        if t.raw("xi_bar", None) is None
        else t.number("xi_bar", low=0.0, strict_low=False),
        xi_time_constant=t.number("xi_time_constant", 0.5, low=0.0),
        at_bound=t.boolean("at_bound", False),
    )
    t.finish()
    return n


def _centroid(t: _Table) -> CentroidPath:
    c = t.table("centroid")
    path = CentroidPath(
        waypoints=c.array("waypoints", (None, N_DIM), what="a list of [x, y] waypoints"),
        speed=c.number("speed", low=0.0),
        corner_radius=c.number("corner_radius", 0.3, low=0.0, strict_low=False),
        ramp_time=c.number("ramp_time", 2.0, low=0.0),
    )
    c.finish()
    return path


def _formation(t: _Table) -> Formation:
    f = t.table("formation")
    formation = Formation(
        shape=f.string("shape", "polygon", choices=("polygon", "grid", "line")),
        side=f.number("side", low=0.0),
        rotation=f.number("rotation", 0.0),
    )
    f.finish()
    return formation


def _mission(t: _Table, duration: float | None) -> Mission:
    assert t.doc is not None
    path = t.doc.guard(_centroid, t)
    formation = t.doc.guard(_formation, t)
    default = min(5.0, duration / 2) if duration is not None else 5.0
    transient = t.number("transient", default, low=0.0, strict_low=False)
    if duration is not None and t.ok("transient") and transient >= duration:
        t.report("transient", f"expected less than duration = {duration:g}, got {transient:g}")
    t.finish()
    return Mission(path, formation, transient)  # type: ignore[arg-type]


def _obstacle(t: _Table) -> Obstacle:
    pos = t.array("position", (N_DIM,), what="an [x, y] pair")
    radius = t.number("radius", low=0.0)
    safe = t.number("safe_distance", low=0.0)
    if t.ok("radius", "safe_distance") and safe <= radius:
        t.report(
            "safe_distance",
            f"expected more than radius = {radius:g} (it is measured from "
            f"the cylinder's axis to the robot's centre), got {safe:g}",
        )
    act = t.number("activation_distance", safe + 0.1, low=0.0)
    if t.ok("safe_distance", "activation_distance") and act < safe:
        t.report("activation_distance", f"expected at least safe_distance = {safe:g}, got {act:g}")
    height = t.number("height", 0.3, low=0.0)
    t.finish()
    return Obstacle(pos, radius, safe, act, height)


def _fault(t: _Table, n: int | None, duration: float | None) -> Fault:
    robot = t.integer("robot")
    if n is not None and t.ok("robot") and not 1 <= robot <= n:
        t.report("robot", f"robot {robot} out of range: robots are numbered 1..{n}")
    kind = t.string("kind", choices=("bias", "stop"))
    at = t.number("t", low=0.0, strict_low=False)
    if duration is not None and t.ok("t") and at >= duration:
        t.report("t", f"fault at {at:g} s is after the end of the run (duration = {duration:g} s)")
    if not t.ok("kind"):
        t.used.update(t.data)  # which keys belong here depends on the kind
        return Fault(robot - 1, kind, at)
    if kind == "bias":
        value = t.array("value", (N_DIM,), what="an [x, y] pair in m/s")
        tau = t.number("time_constant", 0.0, low=0.0, strict_low=False)
        fault = Fault(robot - 1, kind, at, value, tau)
    else:  # a stop fault has no bias; zeros are accepted (Scenario.to_dict writes them)
        value = t.array("value", (N_DIM,), [0.0, 0.0], what="an [x, y] pair")
        if t.ok("value") and np.any(value != 0):
            t.report(
                "value", f"expected [0.0, 0.0] or no value for a stop fault, got {value.tolist()}"
            )
        tau = t.number("time_constant", 0.0, low=0.0, strict_low=False)
        if t.ok("time_constant") and tau != 0:
            t.report(
                "time_constant", f"expected 0 or no time_constant for a stop fault, got {tau:g}"
            )
        fault = Fault(robot - 1, kind, at)
    t.finish()
    return fault


def _fdir(t: _Table) -> Fdir:
    safe = t.number("excluded_safe_distance", 0.35, low=0.0)
    f = Fdir(
        detection_window=t.number("detection_window", 0.2, low=0.0, strict_low=False),
        dt_d_max=_dt_d_max(t),
        initial_error_bound=_initial_error_bound(t),
        replan_time=t.number("replan_time", 4.0, low=0.0, strict_low=False),
        excluded_safe_distance=safe,
        excluded_activation_distance=t.number(
            "excluded_activation_distance",
            safe + 0.1,
            low=safe if t.ok("excluded_safe_distance") else 0.0,
            strict_low=False,
        ),
        phi_low_pass=t.number("phi_low_pass", 0.0, low=0.0, strict_low=False),
        enabled=t.boolean("enabled", True),
        compensate=t.boolean("compensate", True),
        isolation=t.string(
            "isolation", "pairwise", choices=("pairwise", "exclusive", "exclusive_history")
        ),
        reference_fault=t.number("reference_fault", 0.0, low=0.0, strict_low=False),
        input=t.string("input", "applied", choices=("applied", "nominal")),
        drive_lag=_drive_lag(t),
        drive_accel=_number_or_word(
            t, "drive_accel", "robot", "an acceleration in m/s²", strict_low=False
        ),
        max_faults=_max_faults(t),
        self_exclusion=t.boolean("self_exclusion", False),
        postpone_on_contact=t.boolean("postpone_on_contact", True),
        excluded_relay=t.boolean("excluded_relay", False),
    )
    t.finish()
    return f


def _max_faults(t: _Table) -> int | str:
    """How many robots may be faulty at once: a whole number ≥ 1, or "auto"."""
    raw = t.data.get("max_faults", "auto")
    t.raw("max_faults", "auto")
    if raw == "auto":
        return "auto"
    if isinstance(raw, bool) or not isinstance(raw, int) or raw < 1:
        t.report("max_faults", f'expected a whole number of robots ≥ 1 or "auto", got {raw!r}')
        return "auto"
    return raw


def _number_or_word(
    t: _Table,
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


def _drive_lag(t: _Table) -> float | str:
    """τ of the modelled drive lag in seconds, or "robot" (the robot file's calibration)."""
    return _number_or_word(t, "drive_lag", "robot", "a time constant in s", strict_low=False)


def _initial_error_bound(t: _Table) -> float | str:
    """ε̄ in metres, or "auto" (derived per run from the start positions and the slots)."""
    return _number_or_word(t, "initial_error_bound", "auto", "a distance in m", strict_low=False)


def _dt_d_max(t: _Table) -> float | str:
    """Δt_d,max: seconds, or "auto" (computed per run from the graph and the rule)."""
    return _number_or_word(t, "dt_d_max", "auto", "a number of seconds", absent=5.0)


def _onboard(t: _Table) -> Onboard:
    assert t.doc is not None
    chosen = {}
    for block in BLOCKS:
        name = t.raw(block, "paper")
        problem = check_name(block, name)
        if problem:
            t.report(block, problem)
            name = "paper"
        chosen[block] = name
    params = t.doc.guard(_onboard_params, t) if "params" in t.data else {}
    t.used.add("params")
    t.finish()
    return Onboard(**chosen, params=params or {})


def _onboard_params(t: _Table) -> dict[str, dict[str, Any]]:
    assert t.doc is not None
    p = t.table("params")
    out = {}
    for block in p.data:
        p.used.add(block)
        if block not in BLOCKS:
            p.report(block, f"unknown block (blocks: {', '.join(BLOCKS)})")
            continue
        kwargs = t.doc.guard(_keywords, p, block)
        if kwargs is not None:
            out[block] = kwargs
    return out


def _keywords(p: _Table, block: str) -> dict[str, Any]:
    k = p.table(block)
    for name, value in k.data.items():
        k.used.add(name)
        if not name.isidentifier() or keyword.iskeyword(name):
            k.report(name, f"expected a keyword argument name, got {name!r}")
        elif not _is_toml_value(value):
            k.report(name, f"expected a TOML value, got {type(value).__name__} {value!r}")
    return dict(k.data)


def _is_toml_value(v: Any) -> bool:
    if isinstance(v, list):
        return all(_is_toml_value(x) for x in v)
    if isinstance(v, dict):
        return all(isinstance(k, str) and _is_toml_value(x) for k, x in v.items())
    return isinstance(v, str | int | float | bool | datetime.date | datetime.time)


# --------------------------------------------------------------------------- writing TOML

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
