"""Scenarios: TOML files turned into frozen, validated dataclasses.

A scenario is loaded by name (``scenarios/NAME.toml``) or by path. Every
problem is reported as one :class:`~dftc_mujoco.errors.ScenarioError` whose
message names the file, the key and what was expected. Robots are numbered
from 1 in the file (as in the paper) and from 0 inside the code.
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .errors import ScenarioError
from .graph import Graph
from .paths import SCENARIOS

N_DIM = 2  # planar robots: n = 2 in the paper's notation
_MISSING = object()


def _ro(a: Any) -> np.ndarray:
    arr = np.array(a, dtype=float)
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True)
class Physics:
    """Integration settings: MuJoCo timestep, control period and log rate."""

    timestep: float = 0.002
    control_period: float = 0.01
    log_rate: float = 50.0
    robot_contacts: bool = True

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
    G: np.ndarray  # (2, 2), symmetric positive definite
    theta: float


@dataclass(frozen=True)
class Noise:
    """Bounds of measurement noise (eq. 4) and disturbance (eq. 2)."""

    eta_bar: float
    xi_bar: float | None  # None: the robot model's measured mismatch
    xi_time_constant: float = 0.5
    at_bound: bool = False  # draw η and ξ with norms exactly at η̄ and ξ̄


@dataclass(frozen=True, eq=False)
class CentroidPath:
    """Piecewise-linear waypoints, rounded at the corners, travelled at ``speed``."""

    waypoints: np.ndarray  # (W, 2)
    speed: float
    corner_radius: float = 0.3
    ramp_time: float = 2.0


@dataclass(frozen=True)
class Formation:
    """A regular polygon of side ``side`` rotated by ``rotation`` degrees."""

    shape: str = "polygon"
    side: float = 0.5
    rotation: float = 0.0


@dataclass(frozen=True)
class Mission:
    """Desired centroid path and formation; errors are averaged after ``transient`` s."""

    centroid: CentroidPath
    formation: Formation
    transient: float = 5.0


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
    """An actuator fault on ``robot`` (0-based) starting at ``t``."""

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
    dt_d_max: float = 5.0
    initial_error_bound: float = 1.0
    replan_time: float = 4.0
    excluded_safe_distance: float = 0.35
    excluded_activation_distance: float = 0.45
    phi_low_pass: float = 0.0
    enabled: bool = True
    compensate: bool = True  # false: φ̂ is estimated and logged but not applied


@dataclass(frozen=True, eq=False)
class Scenario:
    """A whole validated scenario."""

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

    def with_overrides(
        self,
        *,
        seed: int | None = None,
        duration: float | None = None,
        robot_model: str | None = None,
    ) -> Scenario:
        """A copy with CLI overrides applied and checked.

        A shorter ``duration`` drops the faults that would start after the new
        end (they cannot happen); :func:`dropped_faults` lists them.
        """
        s = self
        where = f"{self.source} (command line)"
        if seed is not None:
            if seed < 0:
                raise ScenarioError(f"{where}: --seed: expected an integer >= 0, got {seed}")
            s = dataclasses.replace(s, seed=int(seed))
        if duration is not None:
            if not (duration > 0 and math.isfinite(duration)):
                raise ScenarioError(f"{where}: --duration: expected a number > 0, got {duration}")
            kept = tuple(f for f in s.faults if f.t < duration)
            s = dataclasses.replace(s, duration=float(duration), faults=kept)
        if robot_model is not None:
            s = dataclasses.replace(s, team=dataclasses.replace(s.team, robot_model=robot_model))
        return s


def dropped_faults(original: Scenario, current: Scenario) -> list[Fault]:
    """Faults of ``original`` that ``current`` no longer has (cut by a shorter duration)."""
    kept = {id(f) for f in current.faults}
    return [f for f in original.faults if id(f) not in kept]


# --------------------------------------------------------------------------- reading


class _Table:
    """A TOML table read key by key; unread keys are reported as unknown."""

    def __init__(self, file: str, data: Any, path: str):
        self.file = file
        self.path = path
        if not isinstance(data, dict):
            self.fail("", f"expected a table, got {_describe(data)}")
        self.data = data
        self.used: set[str] = set()

    def key(self, name: str) -> str:
        return f"{self.path}.{name}" if self.path else name

    def fail(self, name: str, message: str) -> None:
        where = self.key(name) if name else (self.path or "(top level)")
        raise ScenarioError(f"{self.file}: {where}: {message}")

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
        v = self.raw(name, default)
        if isinstance(v, bool) or not isinstance(v, int | float):
            self.fail(name, f"expected a number, got {_describe(v)}")
        v = float(v)
        if not math.isfinite(v):
            self.fail(name, f"expected a finite number, got {v}")
        if low is not None and (v <= low if strict_low else v < low):
            self.fail(name, f"expected a number {'>' if strict_low else '>='} {low:g}, got {v:g}")
        if high is not None and v > high:
            self.fail(name, f"expected a number <= {high:g}, got {v:g}")
        return v

    def integer(self, name: str, default: Any = _MISSING, *, low: int | None = None) -> int:
        v = self.raw(name, default)
        if isinstance(v, bool) or not isinstance(v, int):
            self.fail(name, f"expected an integer, got {_describe(v)}")
        if low is not None and v < low:
            self.fail(name, f"expected an integer >= {low}, got {v}")
        return int(v)

    def string(self, name: str, default: Any = _MISSING, *, choices: tuple[str, ...] = ()) -> str:
        v = self.raw(name, default)
        if not isinstance(v, str):
            self.fail(name, f"expected a string, got {_describe(v)}")
        if choices and v not in choices:
            self.fail(name, f"expected one of {', '.join(map(repr, choices))}, got {v!r}")
        return v

    def boolean(self, name: str, default: Any = _MISSING) -> bool:
        v = self.raw(name, default)
        if not isinstance(v, bool):
            self.fail(name, f"expected true or false, got {_describe(v)}")
        return v

    def array(
        self, name: str, shape: tuple[int | None, ...], default: Any = _MISSING, what: str = ""
    ) -> np.ndarray:
        """A numeric array; ``None`` in ``shape`` accepts any length >= 1."""
        v = self.raw(name, default)
        arr = _numeric_array(v)
        want = what or _shape_words(shape)
        if (
            arr is None
            or arr.ndim != len(shape)
            or any(
                (s is not None and s != a) or a == 0 for s, a in zip(shape, arr.shape, strict=True)
            )
        ):
            self.fail(name, f"expected {want}, got {_describe(v)}")
        if not np.all(np.isfinite(arr)):
            self.fail(name, f"expected finite numbers, got {v!r}")
        return _ro(arr)

    def gain_matrix(self, name: str) -> np.ndarray:
        """A scalar (meaning scalar x I) or a symmetric positive definite 2x2 matrix."""
        v = self.raw(name)
        if isinstance(v, int | float) and not isinstance(v, bool):
            if not v > 0:
                self.fail(name, f"expected a positive number or a 2x2 matrix, got {v}")
            return _ro(float(v) * np.eye(N_DIM))
        m = _numeric_array(v)
        if m is None or m.shape != (N_DIM, N_DIM):
            self.fail(name, f"expected a positive number or a 2x2 matrix, got {_describe(v)}")
        if not np.allclose(m, m.T) or np.linalg.eigvalsh(m).min() <= 0:
            self.fail(name, f"expected a symmetric positive definite matrix, got {v!r}")
        return _ro(m)

    def table(self, name: str, default: Any = _MISSING) -> _Table:
        return _Table(self.file, self.raw(name, default), self.key(name))

    def tables(self, name: str) -> list[_Table]:
        v = self.raw(name, [])
        if not isinstance(v, list) or not all(isinstance(x, dict) for x in v):
            self.fail(name, f"expected an array of tables ([[{name}]]), got {_describe(v)}")
        return [_Table(self.file, x, f"{self.key(name)}[{k + 1}]") for k, x in enumerate(v)]

    def finish(self) -> None:
        unknown = sorted(set(self.data) - self.used)
        if unknown:
            known = ", ".join(sorted(self.used)) or "none"
            self.fail(unknown[0], f"unknown key (known keys here: {known})")


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


def load(name_or_path: str | Path) -> Scenario:
    """Load and validate a scenario by name or path."""
    path = resolve(name_or_path)
    try:
        with open(path, "rb") as fh:
            data = tomllib.load(fh)
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(f"{path}: not valid TOML: {exc}") from None
    except OSError as exc:
        raise ScenarioError(f"{path}: cannot read: {exc.strerror}") from None
    return from_dict(data, source=str(path))


def from_dict(data: dict[str, Any], source: str = "<memory>") -> Scenario:
    """Validate a parsed TOML document (as :func:`tomllib.loads` returns it)."""
    top = _Table(source, data, "")
    name = top.string("name")
    description = top.string("description", "")
    duration = top.number("duration", low=0.0)
    seed = top.integer("seed", 0, low=0)

    physics = _physics(top.table("physics", {}))
    mission = _mission(top.table("mission"), duration)
    team = _team(top.table("team"), mission, seed)
    gains = _gains(top.table("gains"))
    noise = _noise(top.table("noise"))
    obstacles = tuple(_obstacle(t) for t in top.tables("obstacles"))
    faults = tuple(_fault(t, team.robots, duration) for t in top.tables("faults"))
    fdir = _fdir(top.table("fdir", {}))
    top.finish()
    # Forward Euler on d/dt ŷ = k_o r is stable when every eigenvalue z of
    # k_o (L + Πₖ) satisfies |1 − dt z| < 1; Gershgorin's discs guarantee it
    # when k_o dt (2 d_max + 1) < 2.
    step_gain = gains.ko * physics.control_period * (2 * team.graph.in_degree().max() + 1)
    if step_gain >= 2:
        raise ScenarioError(
            f"{source}: gains.ko: the observer update is unstable at this control period: "
            f"ko * control_period * (2 * max in-degree + 1) = {step_gain:g}, expected < 2; "
            "lower ko or physics.control_period"
        )
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
        obstacles,
        faults,
        fdir,
        source,
    )


def _physics(t: _Table) -> Physics:
    timestep = t.number("timestep", 0.002, low=0.0, high=0.1)
    period = t.number("control_period", 0.01, low=0.0, high=1.0)
    ratio = period / timestep
    if ratio < 1 - 1e-9 or abs(ratio - round(ratio)) > 1e-6:
        t.fail(
            "control_period",
            f"expected a whole multiple of timestep = {timestep:g}, got {period:g}",
        )
    log_rate = t.number("log_rate", 50.0, low=0.0)
    if log_rate > 1.0 / period + 1e-9:
        t.fail(
            "log_rate", f"expected at most the control rate {1.0 / period:g} Hz, got {log_rate:g}"
        )
    contacts = t.boolean("robot_contacts", True)
    t.finish()
    return Physics(timestep, period, log_rate, contacts)


def _team(t: _Table, mission: Mission, seed: int) -> Team:
    n = t.integer("robots", low=2)
    model = t.string("robot_model", "disk")
    x0 = _initial_positions(t, n, mission, seed)
    raw = t.raw("graph")
    family = "explicit"
    if isinstance(raw, dict):
        graph, family = _generated_graph(t.table("graph"), n, x0, seed)
    else:
        graph = _edge_list(t, raw, n)
    if not graph.is_strongly_connected():
        t.fail(
            "graph",
            "expected a strongly connected graph (a directed path from every "
            "robot to every other); the observer cannot converge otherwise",
        )
    t.finish()
    return Team(n, model, x0, graph, family)


def _initial_positions(t: _Table, n: int, mission: Mission, seed: int) -> np.ndarray:
    """A list of N [x, y], or {layout = "formation", jitter = m}: the planned slots at t = 0."""
    raw = t.raw("initial_positions")
    if not isinstance(raw, dict):
        return t.array(
            "initial_positions",
            (n, N_DIM),
            what=f"a list of {n} [x, y] pairs (team.robots = {n}), or a table "
            '{layout = "formation", jitter = ...}',
        )
    lay = t.table("initial_positions")
    lay.string("layout", choices=("formation",))
    jitter = lay.number("jitter", 0.0, low=0.0, strict_low=False)
    lay.finish()
    from .mission import formation_offsets

    start = np.asarray(mission.centroid.waypoints[0])
    rng = np.random.default_rng([seed, 7])
    pts = start + formation_offsets(mission.formation, n) + rng.uniform(-jitter, jitter, (n, 2))
    return _ro(pts)


def _generated_graph(g: _Table, n: int, x0: np.ndarray, seed: int) -> tuple[Graph, str]:
    """{family = "ring_chords", chords = [...]}, {family = "random", in_degree = d}
    or {family = "knn", k = k}."""
    from .graph import k_nearest, random_strongly_connected, ring_with_chords

    family = g.string("family", choices=("ring_chords", "random", "knn"))
    if family == "ring_chords":
        chords = g.raw("chords", [])
        if not isinstance(chords, list) or not all(
            isinstance(c, int) and not isinstance(c, bool) and 1 <= c < n for c in chords
        ):
            g.fail("chords", f"expected a list of integers 1..{n - 1}, got {_describe(chords)}")
        graph = ring_with_chords(n, tuple(chords))
    elif family == "random":
        d = g.integer("in_degree", low=1)
        graph = random_strongly_connected(n, d, np.random.default_rng([seed, 11]))
    else:
        graph = k_nearest(np.asarray(x0), g.integer("k", low=1))
    g.finish()
    return graph, family


def _edge_list(t: _Table, raw_edges: Any, n: int) -> Graph:
    if not isinstance(raw_edges, list) or not raw_edges:
        t.fail(
            "graph",
            f"expected a non-empty list of [from, to] robot pairs or a table "
            f"{{family = ...}}, got {_describe(raw_edges)}",
        )
    edges: list[tuple[int, int]] = []
    for k, e in enumerate(raw_edges):
        key = f"graph[{k + 1}]"
        if (
            not isinstance(e, list)
            or len(e) != 2
            or not all(isinstance(v, int) and not isinstance(v, bool) for v in e)
        ):
            t.fail(key, f"expected a [from, to] pair of robot numbers, got {_describe(e)}")
        a, b = e
        for v in (a, b):
            if not 1 <= v <= n:
                t.fail(key, f"robot {v} out of range: robots are numbered 1..{n}")
        if a == b:
            t.fail(key, f"edge [{a}, {b}] goes from a robot to itself")
        if (a - 1, b - 1) in edges:
            t.fail(key, f"edge [{a}, {b}] appears twice")
        edges.append((a - 1, b - 1))
    return Graph(n, tuple(edges))


def _gains(t: _Table) -> Gains:
    g = Gains(
        kc=t.number("kc", low=0.0),
        ko=t.number("ko", low=0.0),
        K=t.gain_matrix("K"),
        G=t.gain_matrix("G"),
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


def _mission(t: _Table, duration: float) -> Mission:
    c = t.table("centroid")
    path = CentroidPath(
        waypoints=c.array("waypoints", (None, N_DIM), what="a list of [x, y] waypoints"),
        speed=c.number("speed", low=0.0),
        corner_radius=c.number("corner_radius", 0.3, low=0.0, strict_low=False),
        ramp_time=c.number("ramp_time", 2.0, low=0.0),
    )
    c.finish()
    f = t.table("formation")
    formation = Formation(
        shape=f.string("shape", "polygon", choices=("polygon", "grid", "line")),
        side=f.number("side", low=0.0),
        rotation=f.number("rotation", 0.0),
    )
    f.finish()
    transient = t.number("transient", min(5.0, duration / 2), low=0.0, strict_low=False)
    if transient >= duration:
        t.fail("transient", f"expected less than duration = {duration:g}, got {transient:g}")
    t.finish()
    return Mission(path, formation, transient)


def _obstacle(t: _Table) -> Obstacle:
    pos = t.array("position", (N_DIM,), what="an [x, y] pair")
    radius = t.number("radius", low=0.0)
    safe = t.number("safe_distance", low=0.0)
    if safe <= radius:
        t.fail(
            "safe_distance",
            f"expected more than radius = {radius:g} (it is measured from "
            f"the cylinder's axis to the robot's centre), got {safe:g}",
        )
    act = t.number("activation_distance", safe + 0.1, low=0.0)
    if act < safe:
        t.fail("activation_distance", f"expected at least safe_distance = {safe:g}, got {act:g}")
    height = t.number("height", 0.3, low=0.0)
    t.finish()
    return Obstacle(pos, radius, safe, act, height)


def _fault(t: _Table, n: int, duration: float) -> Fault:
    robot = t.integer("robot")
    if not 1 <= robot <= n:
        t.fail("robot", f"robot {robot} out of range: robots are numbered 1..{n}")
    kind = t.string("kind", choices=("bias", "stop"))
    at = t.number("t", low=0.0, strict_low=False)
    if at >= duration:
        t.fail("t", f"fault at {at:g} s is after the end of the run (duration = {duration:g} s)")
    if kind == "bias":
        value = t.array("value", (N_DIM,), what="an [x, y] pair in m/s")
        tau = t.number("time_constant", 0.0, low=0.0, strict_low=False)
        fault = Fault(robot - 1, kind, at, value, tau)
    else:
        fault = Fault(robot - 1, kind, at)
    t.finish()
    return fault


def _fdir(t: _Table) -> Fdir:
    safe = t.number("excluded_safe_distance", 0.35, low=0.0)
    f = Fdir(
        detection_window=t.number("detection_window", 0.2, low=0.0, strict_low=False),
        dt_d_max=t.number("dt_d_max", 5.0, low=0.0),
        initial_error_bound=t.number("initial_error_bound", 1.0, low=0.0, strict_low=False),
        replan_time=t.number("replan_time", 4.0, low=0.0, strict_low=False),
        excluded_safe_distance=safe,
        excluded_activation_distance=t.number(
            "excluded_activation_distance", safe + 0.1, low=safe, strict_low=False
        ),
        phi_low_pass=t.number("phi_low_pass", 0.0, low=0.0, strict_low=False),
        enabled=t.boolean("enabled", True),
        compensate=t.boolean("compensate", True),
    )
    t.finish()
    return f
