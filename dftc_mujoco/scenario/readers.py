"""Reading a scenario document: one reader per table, each checking its keys (types, ranges,
what they must agree with) into the scenario's parts."""

from __future__ import annotations

import datetime
import keyword
import math
import re
from typing import Any, cast

import numpy as np

from ..blocks import BLOCKS, check_name
from ..core.graph import Graph
from ..core.mission import ARENA_HALF, CentroidPath, Formation, Mission, formation_offsets
from ..runtime.tomlcheck import N_DIM, Doc, Table, _ro, describe
from ..runtime.tomlcheck import number_or_word as _number_or_word
from .faults import read_fault, timing_problem
from .network import read_network
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

NAME_PATTERN = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,99}$")


def name_problem(name: str) -> str | None:
    """Why ``name`` cannot name an output folder (it becomes ``renders/<name>``), or None."""
    if NAME_PATTERN.match(name) and ".." not in name:
        return None
    return (
        "expected a plain name (letters, digits, '_', '-', '.'; no path separators or '..', "
        f"at most 100 characters): it names the output folder renders/<name>, got {name!r}"
    )


def _across_tables(
    doc: Doc,
    duration: float,
    physics: Physics | None,
    mission: Mission | None,
    team: Team | None,
    gains: Gains | None,
    network: Network | None,
    all_faults: tuple[Fault | RadioFault | None, ...] | None,
) -> None:
    """The checks that read several tables: the observer's stability at the control period,
    the network's and the radio faults' links against the graph, the duration, the faults'
    timing and the path's ramp against the period (each recorded in ``doc``)."""
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
    if network is not None and team is not None and team.graph is not None:
        edges = set(team.graph.edges)
        for k, (link, _) in enumerate(network.link_loss):
            if link not in edges:
                doc.record(
                    f"network.links[{k + 1}].link",
                    f"[{link[0] + 1}, {link[1] + 1}] is not a link of team.graph "
                    "([from, to], robots numbered from 1)",
                )
        for k, f in enumerate(all_faults or ()):
            if isinstance(f, RadioFault) and f.kind == "link_down" and f.link not in edges:
                doc.record(
                    f"faults[{k + 1}].link",
                    f"[{f.link[0] + 1}, {f.link[1] + 1}] is not a link of team.graph "
                    "([from, to], robots numbered from 1)",
                )
    if (
        physics is not None
        and doc.ok("duration", "physics.control_period")
        and duration < physics.control_period * (1 - 1e-9)
    ):  # no period would run: the log would hold t = 0 alone
        doc.record(
            "duration",
            f"expected at least one control period ({physics.control_period:g} s), got "
            f"{duration:g}",
        )
    if physics is not None and doc.ok("duration", "physics.control_period"):
        for k, f in enumerate(all_faults or ()):  # the table's place among [[faults]]
            if isinstance(f, Fault):
                timing = timing_problem(f, physics.control_period, duration)
                if timing is not None:
                    key, why = timing
                    doc.record(f"faults[{k + 1}].{key}", f"the {f.kind} fault: {why}")
    if (
        mission is not None
        and physics is not None
        and doc.ok("mission.centroid.ramp_time", "physics.control_period")
        and mission.centroid.ramp_time < physics.control_period
    ):  # the path's speed cannot ramp within less than a period (and its table would not end)
        doc.record(
            "mission.centroid.ramp_time",
            f"expected at least control_period = {physics.control_period:g} s, got "
            f"{mission.centroid.ramp_time:g}",
        )


def document(doc: Doc, data: Any) -> dict[str, Any] | None:
    """Every table of a scenario document read and checked: the Scenario's fields, or None
    when a problem was recorded (``doc`` holds them)."""
    top = Table(doc.file, data, "", doc)
    name = top.string("name")
    problem = name_problem(name) if top.ok("name") else None
    if problem:
        top.report("name", problem)
    description = top.string("description", "")
    duration = top.number("duration", low=0.0)
    seed = top.integer("seed", 0, low=0, high=2**63 - 1)
    known_duration = duration if top.ok("duration") else None

    physics = doc.guard(lambda: _physics(top.table("physics", {})))
    mission = doc.guard(lambda: _mission(top.table("mission"), known_duration))
    team = doc.guard(lambda: _team(top.table("team"), mission, seed))
    gains = doc.guard(lambda: _gains(top.table("gains")))
    noise = doc.guard(lambda: _noise(top.table("noise")))
    obstacles = doc.guard(lambda: tuple(doc.guard(_obstacle, t) for t in top.tables("obstacles")))
    robots = team.robots if team is not None and doc.ok("team.robots") else None
    all_faults = doc.guard(
        lambda: tuple(
            doc.guard(read_fault, t, robots, known_duration) for t in top.tables("faults")
        )
    )
    faults = radio = None
    if all_faults is not None:
        faults = tuple(f for f in all_faults if isinstance(f, Fault))
        radio = tuple(f for f in all_faults if isinstance(f, RadioFault))
    network = doc.guard(lambda: read_network(top.table("network", {}), physics, radio or ()))
    fdir = doc.guard(lambda: _fdir(top.table("fdir", {})))
    onboard = doc.guard(lambda: _onboard(top.table("onboard", {})))
    supervision = doc.guard(lambda: _supervision(top.table("supervisor", {})))
    top.finish()
    _across_tables(doc, duration, physics, mission, team, gains, network, all_faults)
    if doc.problems:
        return None
    # every reader returned its value where it recorded no problem
    assert physics is not None and team is not None and gains is not None
    assert noise is not None and mission is not None and fdir is not None
    assert onboard is not None and supervision is not None
    assert obstacles is not None and faults is not None
    return {
        "name": name,
        "description": description,
        "duration": duration,
        "seed": seed,
        "physics": physics,
        "team": team,
        "gains": gains,
        "noise": noise,
        "mission": mission,
        "obstacles": cast(tuple[Obstacle, ...], obstacles),
        "faults": faults,
        "fdir": fdir,
        "source": doc.file,
        "onboard": onboard,
        "supervisor": supervision,
        "network": network,
    }


def _supervision(t: Table) -> Supervision:
    distance = _number_or_word(t, "teammate_distance", "auto", "a distance in m")
    s = Supervision(t.boolean("avoid_teammates", True), distance)
    t.finish()
    return s


#: physics steps per control period beyond which a timestep is a typo (1e-7 s at 10 ms is 1e5
#: steps, about an hour for a minute of paper_case, and is warned about; 1e-300 overflowed)
MAX_SUBSTEPS = 1e6


def _physics(t: Table) -> Physics:
    timestep = t.number("timestep", 0.002, low=0.0, high=0.1)
    period = t.number("control_period", 0.01, low=0.0, high=1.0)
    ratio = period / timestep
    if t.ok("timestep", "control_period") and ratio > MAX_SUBSTEPS:
        t.report(
            "timestep",
            f"expected at least control_period / {MAX_SUBSTEPS:g} = {period / MAX_SUBSTEPS:g} s "
            f"(at most {MAX_SUBSTEPS:g} physics steps per control period), got {timestep:g}",
        )
    elif t.ok("timestep", "control_period") and (
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


#: the largest team: every robot estimates the whole team, 15·16·N² bytes (6 GB at 5000)
MAX_ROBOTS = 5000


def _off_the_floor(t: Table, key: str, points: np.ndarray, what: str) -> None:
    """Report the first of ``points`` (k, 2) beyond the arena's floor (±ARENA_HALF)."""
    far = np.flatnonzero(np.abs(points).max(axis=1) > ARENA_HALF)
    if len(far):
        k = int(far[0])
        x, y = points[k]
        more = f" (and {len(far) - 1} more)" if len(far) > 1 else ""
        t.report(
            key,
            f"{what.format(k + 1)} at [{x:.4g}, {y:.4g}] is off the arena's floor, which ends "
            f"at ±{ARENA_HALF:g} m{more}",
        )


_FAMILIES = ("explicit", "ring_chords", "random", "knn", "line")


def _robot_model(t: Table, n: int | None) -> str | tuple[str, ...]:
    """``team.robot_model``: one model for the whole team, or a list of one per robot (a
    mixed team); a list of one name is that name."""
    raw = t.data.get("robot_model", "disk")
    if not isinstance(raw, list):
        return t.string("robot_model", "disk")
    t.raw("robot_model")
    names = tuple(raw)
    if not names or not all(isinstance(x, str) and x for x in names):
        t.report("robot_model", f"expected a model name or a list of names, got {describe(raw)}")
        return "disk"
    if n is not None and len(names) != n:
        t.report(
            "robot_model",
            f"expected one model per robot (team.robots = {n}) or a single name, got {len(names)}",
        )
        return "disk"
    return names[0] if len(set(names)) == 1 else names


def _team(t: Table, mission: Mission | None, seed: int) -> Team:
    """The team; its graph is None when a problem (recorded) left it unknown."""
    assert t.doc is not None
    n = t.integer("robots", low=2, high=MAX_ROBOTS)
    known_n = n if t.ok("robots") else None
    model = _robot_model(t, known_n)
    x0 = t.doc.guard(_initial_positions, t, known_n, mission, seed)
    graph, family = t.doc.guard(_graph, t, known_n, x0, seed) or (None, None)
    if t.given("graph_family"):
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
    t: Table, n: int | None, mission: Mission | None, seed: int
) -> np.ndarray | None:
    """A list of N [x, y], or a generated layout: {layout = "formation", jitter = m} (the
    planned slots at t = 0, each moved by up to ±jitter per axis; with ``spacing``, robots at
    least that far apart), {layout = "random", spread = m, spacing = m} (uniform in a square
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
        if t.ok("initial_positions"):
            _off_the_floor(t, "initial_positions", x0, "robot {}")
        return x0 if t.ok("initial_positions") else None
    lay = t.table("initial_positions")
    layout = lay.string("layout", choices=("formation", "random", "circle"))
    jitter = lay.number("jitter", 0.0, low=0.0, strict_low=False)
    spread = lay.number("spread", 5.0, low=0.0)  # random: half-width of the square [m]
    # the least distance between two robots [m] (random; formation: only where given)
    spacing = lay.number("spacing", 0.5, low=0.0, strict_low=False)
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
        corners = start + np.array([[-spread, -spread], [spread, spread]])
        _off_the_floor(lay, "spread", corners, "the square's corner {}")
        room = (2 * spread / spacing + 1) ** 2 if spacing > 0 else math.inf
        if lay.ok("spread") and n > room:  # not even a square grid of that pitch holds them
            lay.report(
                "spread",
                f"{n} robots {spacing:g} m apart do not fit within ±{spread:g} m (at most "
                f"{int(room)}): raise spread or lower spacing",
            )
        if not lay.ok("spread"):
            return None
        pts: list[np.ndarray] = []
        cells: dict[tuple[int, int], list[np.ndarray]] = {}  # the points by spacing-wide cell
        size = spacing if spacing > 0 else 1.0
        for _ in range(2000 * n):
            p = start + rng.uniform(-spread, spread, 2)
            cx, cy = int(p[0] // size), int(p[1] // size)
            near = (
                q for i in (-1, 0, 1) for j in (-1, 0, 1) for q in cells.get((cx + i, cy + j), ())
            )
            if spacing <= 0 or all(np.hypot(*(p - q)) >= spacing for q in near):
                pts.append(p)
                cells.setdefault((cx, cy), []).append(p)
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
        pts_ = start + r * np.c_[np.cos(ang), np.sin(ang)]
        _off_the_floor(t, "initial_positions", pts_, "the layout puts robot {}")
        return _ro(pts_)
    if "spacing" not in lay.data:  # each slot moved by up to ±jitter per axis
        pts_ = start + offsets + rng.uniform(-jitter, jitter, (n, 2))
    else:  # and each robot at least ``spacing`` from the ones placed before it
        pts_ = np.empty((n, 2))
        for i in range(n):
            for _ in range(1000):
                pts_[i] = start + offsets[i] + rng.uniform(-jitter, jitter, 2)
                if i == 0 or np.hypot(*(pts_[:i] - pts_[i]).T).min() >= spacing:
                    break
            else:
                lay.report(
                    "spacing",
                    f"cannot keep robot {i + 1} {spacing:g} m from the others within ±{jitter:g}"
                    " m of its slot: lower spacing or jitter",
                )
                return None
    _off_the_floor(t, "initial_positions", pts_, "the layout puts robot {}")
    return _ro(pts_)


def _graph(
    t: Table, n: int | None, x0: np.ndarray | None, seed: int
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
    g: Table, n: int | None, x0: np.ndarray | None, seed: int
) -> tuple[Graph | None, str | None]:
    """{family = "ring_chords", chords = [...]}, {family = "random", in_degree = d},
    {family = "knn", k = k} or {family = "line"} (i ⇄ i + 1: every inner robot a cut)."""
    from ..core.graph import (
        k_nearest,
        line_with_back_links,
        random_strongly_connected,
        ring_with_chords,
    )

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
            g.report("chords", f"expected a list of integers 1..{high}, got {describe(chords)}")
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


def _edge_list(t: Table, raw_edges: Any, n: int | None) -> Graph | None:
    if not isinstance(raw_edges, list) or not raw_edges:
        t.fail(
            "graph",
            f"expected a non-empty list of [from, to] robot pairs or a table "
            f"{{family = ...}}, got {describe(raw_edges)}",
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
            t.report(key, f"expected a [from, to] pair of robot numbers, got {describe(e)}")
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


def _gains(t: Table) -> Gains:
    g = Gains(
        kc=t.number("kc", low=0.0),
        ko=t.number("ko", low=0.0),
        K=t.gain_matrix("K"),
        G=None if t.raw("G", None) == "auto" else t.gain_matrix("G", auto=True),
        theta=t.number("theta", 2.0, low=0.0),
    )
    t.finish()
    return g


def _noise(t: Table) -> Noise:
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


def _centroid(t: Table) -> CentroidPath:
    c = t.table("centroid")
    waypoints = c.array("waypoints", (None, N_DIM), what="a list of [x, y] waypoints")
    if c.ok("waypoints"):
        _off_the_floor(c, "waypoints", waypoints, "waypoint {}")
    path = CentroidPath(
        waypoints=waypoints,
        speed=c.number("speed", low=0.0),
        corner_radius=c.number("corner_radius", 0.3, low=0.0, strict_low=False),
        ramp_time=c.number("ramp_time", 2.0, low=0.0),
        governor=c.boolean("governor", True),
    )
    c.finish()
    return path


def _formation(t: Table) -> Formation:
    f = t.table("formation")
    formation = Formation(
        shape=f.string("shape", "polygon", choices=("polygon", "grid", "line")),
        side=f.number("side", low=0.0),
        rotation=f.number("rotation", 0.0),
    )
    f.finish()
    return formation


def _mission(t: Table, duration: float | None) -> Mission:
    assert t.doc is not None
    path = t.doc.guard(_centroid, t)
    formation = t.doc.guard(_formation, t)
    default = min(5.0, duration / 2) if duration is not None else 5.0
    transient = t.number("transient", default, low=0.0, strict_low=False)
    if duration is not None and t.ok("transient") and transient >= duration:
        t.report("transient", f"expected less than duration = {duration:g}, got {transient:g}")
    t.finish()
    return Mission(path, formation, transient)  # type: ignore[arg-type]


def _obstacle(t: Table) -> Obstacle:
    pos = t.array("position", (N_DIM,), what="an [x, y] pair")
    if t.ok("position"):
        _off_the_floor(t, "position", pos[None], "the cylinder")
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


def _fdir(t: Table) -> Fdir:
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
        start_ramp=t.boolean("start_ramp", True),
        self_exclusion=t.boolean("self_exclusion", False),
        postpone_on_contact=t.boolean("postpone_on_contact", True),
        confirm_by_estimate=t.boolean("confirm_by_estimate", True),
        excluded_relay=t.boolean("excluded_relay", False),
        rewire=t.string("rewire", "auto", choices=("auto", "adopt", "relay", "none")),
    )
    if f.excluded_relay and f.rewire not in ("auto", "relay"):
        t.report(
            "excluded_relay",
            f'true means rewire = "relay", but rewire = "{f.rewire}"; keep one of the two',
        )
    t.finish()
    return f


def _max_faults(t: Table) -> int | str:
    """How many robots may be faulty at once: a whole number ≥ 1, or "auto"."""
    raw = t.data.get("max_faults", "auto")
    t.raw("max_faults", "auto")
    if raw == "auto":
        return "auto"
    if isinstance(raw, bool) or not isinstance(raw, int) or raw < 1:
        t.report("max_faults", f'expected a whole number of robots ≥ 1 or "auto", got {raw!r}')
        return "auto"
    return raw


def _drive_lag(t: Table) -> float | str:
    """τ of the modelled drive lag in seconds, or "robot" (the robot file's calibration)."""
    return _number_or_word(t, "drive_lag", "robot", "a time constant in s", strict_low=False)


def _initial_error_bound(t: Table) -> float | str:
    """ε̄ in metres, or "auto" (derived per run from the start positions and the slots)."""
    return _number_or_word(t, "initial_error_bound", "auto", "a distance in m", strict_low=False)


def _dt_d_max(t: Table) -> float | str:
    """Δt_d,max: seconds, or "auto" (computed per run from the graph and the rule)."""
    return _number_or_word(t, "dt_d_max", "auto", "a number of seconds", absent=5.0)


def _onboard(t: Table) -> Onboard:
    assert t.doc is not None
    chosen = {}
    for block in BLOCKS:
        default = Onboard.thresholds if block == "thresholds" else "paper"
        name = t.raw(block, default)
        problem = check_name(block, name)
        if problem:
            t.report(block, problem)
            name = default
        chosen[block] = name
    params = t.doc.guard(_onboard_params, t) if "params" in t.data else {}
    t.used.add("params")
    t.finish()
    return Onboard(**chosen, params=params or {})


def _onboard_params(t: Table) -> dict[str, dict[str, Any]]:
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


def _keywords(p: Table, block: str) -> dict[str, Any]:
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
