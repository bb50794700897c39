"""Campaign specs (TOML) and the parameters of each run.

name = "stop_every_robot"
scenario = "paper_case"          # base scenario: name or path (relative to this file)
runs = 40
seed = 7                         # campaign seed: run i draws from (seed, i)
[set]                            # merged into the base scenario for every run
duration = 60.0
[vary]
seed = true                      # a different scenario seed per run (default)
fault_kind = ["stop"]            # choices among stop, bias, none, two_stops, silent (the
                                 # robot's radio falls silent, it stops 5-15 s later),
                                 # loss_of_effectiveness (10-60 % left), intermittent (a stop
                                 # half of every 1-4 s), sensor_bias (bias_magnitude m) and
                                 # sensor_drift (bias_magnitude / 10 m/s)
faulty_robot = "any"             # or a list of robot numbers
fault_time = [15.0, 45.0]        # uniform range [s]
bias_magnitude = [0.05, 1.5]     # uniform range [m/s], random direction
robots = [4, 8, 16]              # choices of N (layout and graph then generated)
graph_family = ["ring_chords", "random", "knn", "line"]  # or "ring"
eta_bar = [0.0005, 0.002]        # uniform ranges
xi_bar = [0.002, 0.01]
"gains.ko" = [3.0, 6.0]          # any scenario key by dotted path (quoted): a list
"onboard.thresholds" = ["paper", "mylab.fdi:Mine"]   # of choices, one drawn per run;
obstacles = [[], [{ position = [3, 0], radius = 0.3, safe_distance = 0.55 }]]  # and duration
design = "random"                # or "grid": every combination of the lists above
                                 # (robots, graph_family, fault_kind, dotted keys) in
                                 # turn, run i taking combination i mod their count
[vary.graph]                     # parameters of generated graphs
chords = [2]
in_degree = 2
k = 2
[methods.paper]                  # methods compared on the same draws: each an [onboard]
[methods.tight]                  # table (blocks and [methods.NAME.params.BLOCK], and
thresholds = "l1"                # [methods.NAME.fdir] over the scenario's [fdir]); run i is
[methods.none]                   # draw i // M with method i % M, so every method meets the
decision = "none"                # same seeds, layouts and faults; rows carry `method`
                                 # ("none": no detection, no isolation, to compare with)

Dotted keys are drawn after every other parameter (so adding one does not
change the other draws of a campaign), recorded in the run's parameters under
the dotted key and applied last, with :func:`dftc_mujoco.scenario.apply_overrides`.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .. import scenario as scenario_mod
from ..errors import ScenarioError
from ..runtime.tomlcheck import Table, describe, read_toml

#: the fault zoo's kinds a campaign may draw (besides stop, bias, two stops and silent radios)
ZOO_KINDS = ("loss_of_effectiveness", "intermittent", "sensor_bias", "sensor_drift")
FAULT_KINDS = ("stop", "bias", "none", "two_stops", "silent", *ZOO_KINDS)
FAMILIES = ("ring", "ring_chords", "random", "knn", "line")
#: the scenario's top-level keys a [vary] table may draw among choices of, like a dotted key
#: (the others are drawn by the table's own keys: seed, robots, the faults)
TOP_KEYS = ("duration", "obstacles")


@dataclass(frozen=True)
class Spec:
    """A validated campaign spec."""

    name: str
    description: str
    base: dict[str, Any]  # the base scenario as parsed TOML
    base_source: str
    runs: int
    seed: int
    set: dict[str, Any] = field(default_factory=dict)
    vary: dict[str, Any] = field(default_factory=dict)
    source: str = "<memory>"


def load(path: str | Path) -> Spec:
    """Read and validate a campaign spec; errors name the file and the key."""
    path = Path(path)
    if not path.is_file():
        raise ScenarioError(f"{path}: no such campaign spec")
    data = read_toml(path)  # not TOML, not UTF-8, unreadable: one line
    top = Table(str(path), data, "")
    name = top.string("name")
    problem = scenario_mod.name_problem(name)
    if problem:
        top.fail("name", problem)
    description = top.string("description", "")
    base_name = top.string("scenario")
    candidate = path.parent / base_name
    base_path = candidate if candidate.suffix == ".toml" and candidate.is_file() else None
    base_file = scenario_mod.resolve(base_path or base_name)
    base = read_toml(base_file)  # not TOML, not UTF-8, unreadable: one line
    # the base scenario must be valid on its own: its errors name its file, not a run
    scenario_mod.from_dict(copy.deepcopy(base), source=f"{base_file} (base scenario of {path})")
    runs = top.integer("runs", low=1)
    seed = top.integer("seed", 0, low=0, high=2**63 - 1)
    overrides = top.raw("set", {})
    if not isinstance(overrides, dict):
        top.fail("set", f"expected a table of scenario keys, got {describe(overrides)}")
    vary = _vary(top.table("vary", {}))
    methods = top.raw("methods", {})
    if not isinstance(methods, dict) or not all(isinstance(m, dict) for m in methods.values()):
        top.fail("methods", f"expected tables [methods.NAME], got {describe(methods)}")
    for m in methods:
        problem = scenario_mod.name_problem(m)
        if problem:
            top.fail(f"methods.{m}", problem)
    if methods:
        if len(methods) < 2:
            top.fail("methods", "expected at least two methods to compare")
        if runs % len(methods):
            top.fail(
                "runs",
                f"expected a multiple of the {len(methods)} methods (each draw runs "
                f"once per method), got {runs}",
            )
        vary["methods"] = dict(methods)
        _check_methods_not_drawn(path, vary)
    top.finish()
    _check_faulty_robots(path, vary, base)
    _check_team_sizes(path, vary, base, overrides)
    spec = Spec(name, description, base, str(base_file), runs, seed, overrides, vary, str(path))
    scenario_for(spec, draw(spec, 0))  # the scenarios it makes must be valid
    _check_variety(spec)
    _check_choices(spec)
    for i in range(1, min(runs, max(3, len(methods)))):  # every method's scenario is valid
        scenario_for(spec, draw(spec, i))
    return spec


def _method_keys(table: dict[str, Any], prefix: str) -> list[str]:
    """A ``[methods.NAME]`` table's scenario keys, dotted (``fdir`` is the scenario's)."""
    out = []
    for k, v in table.items():
        key = "fdir" if prefix == "onboard" and k == "fdir" else f"{prefix}.{k}"
        out += _method_keys(v, key) if isinstance(v, dict) else [key]
    return out


def _check_methods_not_drawn(path: Path, vary: dict[str, Any]) -> None:
    """A dotted ``[vary]`` key is applied last: one that a method sets too overrides every
    method's value, and the report compares a method with itself."""
    for name, table in vary["methods"].items():
        for mkey in _method_keys(table, "onboard"):
            for vkey in vary.get("scenario_keys", {}):
                a, b = mkey.split("."), vkey.split(".")
                if a[: len(b)] == b[: len(a)]:  # the same key, or one holds the other
                    raise ScenarioError(
                        f'{path}: vary."{vkey}": [methods.{name}] sets {mkey} too; the drawn '
                        "value would override every method's, and the report would compare "
                        "one method with itself: expected the key in [vary] or in each "
                        "[methods.NAME], not both"
                    )


def episodes(base: scenario_mod.Scenario, vary: dict[str, Any] | Any) -> Spec:
    """A spec whose draws are an environment's episodes: ``base`` (a scenario) varied by
    ``vary`` (a campaign's ``[vary]`` table, as a dict), one draw per episode seed
    (:func:`draw` of the spec with that seed, run 0); refused in one line as a spec is."""
    where = f"{base.source} (the environment's vary)"
    data = base.to_dict()
    table = Table(where, dict(vary), "vary")
    v = _vary(table)
    spec = Spec(base.name, "", data, str(base.source), 1, 0, {}, v, where)
    _check_faulty_robots(Path(where), v, data)
    scenario_for(spec, draw(spec, 0))  # a valid scenario, or the line that says why
    _check_choices(spec)
    return spec


def _check_faulty_robots(path: Path, vary: dict[str, Any], base: dict[str, Any]) -> None:
    """``vary.faulty_robot`` must name robots that exist in every team size drawn."""
    robots = vary["faulty_robot"]
    if robots == "any" or set(vary.get("fault_kind", ["base"])) <= {"none", "base"}:
        return
    team = base.get("team", {})
    if "robots" not in vary:
        n = team.get("robots") if isinstance(team, dict) else None
        bad = [r for r in robots if isinstance(n, int) and r > n]
        if bad:
            which = f"robot {bad[0]} does" if len(bad) == 1 else f"robots {bad} do"
            raise ScenarioError(
                f"{path}: vary.faulty_robot: {which} not exist in a team of {n} (the base "
                f"scenario's team.robots); expected robot numbers from 1 to {n}"
            )
        return
    for n in vary["robots"]:
        if not any(r <= n for r in robots):
            raise ScenarioError(
                f"{path}: vary.faulty_robot: none of robots {robots} exists in a team of {n} "
                f"(vary.robots = {vary['robots']}); give at least one from 1 to {n}"
            )


def _check_team_sizes(
    path: Path, vary: dict[str, Any], base: dict[str, Any], overrides: dict[str, Any]
) -> None:
    """``vary.robots`` without ``vary.graph_family`` keeps the base scenario's team.graph: an
    edge list is written for the base's N robots (it failed later as "not strongly
    connected", naming a run)."""
    if "robots" not in vary or "graph_family" in vary:
        return
    team = copy.deepcopy(base.get("team", {}))
    if isinstance(team, dict):
        _merge(team, overrides.get("team", {}) if isinstance(overrides.get("team"), dict) else {})
    graph = team.get("graph") if isinstance(team, dict) else None
    if isinstance(graph, list):
        n = team.get("robots")
        raise ScenarioError(
            f"{path}: vary.robots: the base scenario's team.graph lists the edges of its {n} "
            f"robots, and team sizes {vary['robots']} keep it; expected vary.graph_family "
            f"({', '.join(FAMILIES)}), or a generated team.graph in [set] (e.g. "
            '{family = "random", in_degree = 2})'
        )


def _check_variety(spec: Spec) -> None:
    """Refuse a campaign whose runs would all be one and the same scenario (``[vary] seed =
    false`` and nothing else drawn): N identical copies say nothing N times."""
    if spec.runs < 2:
        return
    first = {k: v for k, v in draw(spec, 0).items() if k != "run"}
    for i in range(1, min(spec.runs, 16)):
        if {k: v for k, v in draw(spec, i).items() if k != "run"} != first:
            return
    raise ScenarioError(
        f"{spec.source}: vary: every one of the {spec.runs} runs would be the same scenario "
        "(seed = false and nothing else varies): set [vary] seed = true, vary something, or "
        "ask for runs = 1"
    )


def _check_choices(spec: Spec) -> None:
    """Every choice of a dotted ``[vary]`` key must give a valid scenario (with run 0's draws)."""
    first = draw(spec, 0)
    for key, choices in spec.vary.get("scenario_keys", {}).items():
        for choice in choices:
            label = f'{spec.source} (vary."{key}" = {choice!r})'
            d = scenario_dict(spec, {**first, key: choice}, where=label)
            scenario_mod.from_dict(d, source=label)


def _vary(t: Table) -> dict[str, Any]:
    v: dict[str, Any] = {"seed": t.boolean("seed", True)}
    v["design"] = t.string("design", "random", choices=("random", "grid"))
    dotted: dict[str, list[Any]] = {}
    for key in t.data:
        if "." in key or key in TOP_KEYS:
            choices = t.raw(key)
            if not isinstance(choices, list) or not choices:
                t.fail(
                    f'"{key}"',
                    f"expected a non-empty list of choices, got {describe(choices)}",
                )
            dotted[key] = choices
    for key, allowed in (("fault_kind", FAULT_KINDS), ("graph_family", FAMILIES)):
        if key in t.data:
            v[key] = _choices(t, key, allowed)
    robot = t.raw("faulty_robot", "any")
    if robot != "any" and not (
        isinstance(robot, list) and robot and all(isinstance(r, int) and r >= 1 for r in robot)
    ):
        t.fail("faulty_robot", f'expected "any" or a list of robot numbers, got {describe(robot)}')
    v["faulty_robot"] = robot
    for key in ("fault_time", "bias_magnitude", "eta_bar", "xi_bar"):
        if key in t.data:
            lo_hi = t.array(key, (2,), what="a [low, high] range")
            if lo_hi[0] > lo_hi[1] or lo_hi[0] < 0:
                t.fail(key, f"expected 0 <= low <= high, got {lo_hi.tolist()}")
            elif key == "bias_magnitude" and lo_hi[1] == 0:
                t.fail(key, f"expected high > 0 (a bias of 0 is no fault), got {lo_hi.tolist()}")
            v[key] = [float(lo_hi[0]), float(lo_hi[1])]
    kinds = set(v.get("fault_kind", ()))
    for key, users in (
        ("faulty_robot", {"stop", "bias", "two_stops", "silent", *ZOO_KINDS}),
        ("fault_time", {"stop", "bias", "two_stops", "silent", *ZOO_KINDS}),
        ("bias_magnitude", {"bias", "sensor_bias", "sensor_drift"}),
    ):  # a key no drawn fault reads was ignored without a word
        if key in t.data and not kinds & users:
            drawn = (
                f"draws only {', '.join(sorted(kinds))}"
                if kinds
                else "is not given (the base scenario's faults run as written)"
            )
            t.fail(
                key,
                f"no run reads it: vary.fault_kind {drawn}; expected fault_kind to include "
                f"one of {', '.join(sorted(users))}",
            )
    if "robots" in t.data:
        ns = t.raw("robots")
        if (
            not isinstance(ns, list)
            or not ns
            or any(not isinstance(n, int) or isinstance(n, bool) or n < 3 for n in ns)
        ):
            t.fail("robots", f"expected a list of team sizes >= 3, got {describe(ns)}")
        v["robots"] = ns
    g = t.table("graph", {})
    chords = g.raw("chords", [2])
    if not isinstance(chords, list) or any(
        isinstance(c, bool) or not isinstance(c, int) or c < 1 for c in chords
    ):
        g.fail("chords", f"expected a list of chord lengths >= 1, got {describe(chords)}")
    v["graph"] = {
        "chords": chords,
        "in_degree": g.integer("in_degree", 2, low=1),
        "k": g.integer("k", 2, low=1),
    }
    g.finish()
    t.finish()
    if dotted:
        v["scenario_keys"] = dotted
    return v


def _choices(t: Table, key: str, allowed: tuple[str, ...]) -> list[str]:
    """A non-empty list whose items are all in ``allowed``."""
    value = t.raw(key)
    if not isinstance(value, list) or not value or any(v not in allowed for v in value):
        t.fail(key, f"expected a list of {', '.join(allowed)}, got {describe(value)}")
    return value


def grid_choice(vary: dict[str, Any], index: int) -> dict[str, Any]:
    """For ``design = "grid"``: the combination of run ``index`` (mixed radix over the lists
    robots, graph_family, fault_kind and the dotted keys, in that order); {} otherwise."""
    if vary.get("design") != "grid":
        return {}
    factors = [(k, vary[k]) for k in ("robots", "graph_family", "fault_kind") if k in vary]
    factors += list(vary.get("scenario_keys", {}).items())
    out: dict[str, Any] = {}
    rest = index
    for key, choices in factors:
        rest, digit = divmod(rest, len(choices))
        out[key] = choices[digit]
    return out


def draw(spec: Spec, index: int) -> dict[str, Any]:
    """The parameters of run ``index`` (0-based): drawn from (campaign seed, index) only; with
    ``[methods]`` from draw ``index // M``, method ``index % M`` (the same draws for every
    method)."""
    v = spec.vary
    methods = list(v.get("methods", {}))
    drawn = index // len(methods) if methods else index
    rng = np.random.default_rng([spec.seed, drawn])
    grid = grid_choice(v, drawn)

    def pick(key: str) -> Any:
        return grid[key] if key in grid else rng.choice(v[key])

    base_team = spec.base.get("team", {})
    n = int(pick("robots")) if "robots" in v else int(base_team.get("robots", 4))
    p: dict[str, Any] = {"run": index, "robots": n}
    if methods:
        p["method"], p["draw"] = methods[index % len(methods)], drawn
    p["seed"] = (
        int(rng.integers(0, 2**31 - 1)) if v.get("seed", True) else int(spec.base.get("seed", 0))
    )
    p["graph_family"] = (
        str(pick("graph_family"))
        if "graph_family" in v
        else ("generated" if "robots" in v else "base")
    )
    kind = str(pick("fault_kind")) if "fault_kind" in v else "base"
    p["fault_kind"] = kind
    if kind in ("stop", "bias", "two_stops", "silent", *ZOO_KINDS):
        choices = (
            list(range(1, n + 1))
            if v["faulty_robot"] == "any"
            else [r for r in v["faulty_robot"] if r <= n]
        )
        p["faulty_robot"] = int(rng.choice(choices))
        lo, hi = v.get("fault_time", [10.0, 10.0])
        p["fault_t"] = round(float(rng.uniform(lo, hi)), 3)
        if kind == "loss_of_effectiveness":
            p["remaining_gain"] = round(float(rng.uniform(0.1, 0.6)), 4)
        if kind == "intermittent":
            p["fault_period"] = round(float(rng.uniform(1.0, 4.0)), 3)
        if kind in ("bias", "sensor_bias", "sensor_drift"):
            lo, hi = v.get("bias_magnitude", [0.3, 0.3])
            p["bias_magnitude"] = round(float(rng.uniform(lo, hi)), 4)
            p["bias_angle"] = round(float(rng.uniform(0, 2 * np.pi)), 4)
        if kind == "two_stops":  # a second robot stops 5-15 s after the first
            others = [r for r in range(1, n + 1) if r != p["faulty_robot"]]
            p["second_robot"] = int(rng.choice(others))
            p["second_t"] = round(p["fault_t"] + float(rng.uniform(5.0, 15.0)), 3)
        if kind == "silent":  # the silent robot stops 5-15 s after its radio
            p["second_robot"] = p["faulty_robot"]
            p["second_t"] = round(p["fault_t"] + float(rng.uniform(5.0, 15.0)), 3)
    for key in ("eta_bar", "xi_bar"):
        if key in v:
            p[key] = round(float(rng.uniform(*v[key])), 6)
    for key, choices in v.get("scenario_keys", {}).items():  # after the draws above
        chosen = grid[key] if key in grid else choices[int(rng.integers(len(choices)))]
        p[key] = copy.deepcopy(chosen)
    return p


def _merge(into: dict[str, Any], extra: dict[str, Any]) -> None:
    for k, val in extra.items():
        if isinstance(val, dict) and isinstance(into.get(k), dict):
            _merge(into[k], val)
        else:
            into[k] = copy.deepcopy(val)


def scenario_dict(spec: Spec, p: dict[str, Any], where: str = "") -> dict[str, Any]:
    """The scenario (as a TOML dict) of one run.

    Args:
        spec: The campaign.
        p: The run's parameters (:func:`draw`).
        where: What errors in dotted ``[vary]`` keys name as the file (default:
            the spec and the run).

    Returns:
        The base scenario with ``[set]``, the drawn parameters and, last, the
        drawn dotted scenario keys applied.
    """
    d = copy.deepcopy(spec.base)
    _merge(d, spec.set)
    d["seed"] = p["seed"]
    d["name"] = f"{spec.name}_{p['run']:05d}"
    team = d.setdefault("team", {})
    n = p["robots"]
    g = spec.vary["graph"]
    family = p["graph_family"]
    if family not in ("base",):
        if "robots" in spec.vary or team.get("robots") != n:
            team["robots"] = n
            team["initial_positions"] = {"layout": "formation", "jitter": 0.05}
        if family == "ring":
            team["graph"] = {"family": "ring_chords", "chords": []}
        elif family == "ring_chords":
            team["graph"] = {"family": "ring_chords", "chords": [c for c in g["chords"] if c < n]}
        elif family == "random":
            team["graph"] = {"family": "random", "in_degree": g["in_degree"]}
        elif family == "knn":
            team["graph"] = {"family": "knn", "k": g["k"]}
        elif family == "line":
            team["graph"] = {"family": "line"}
    kind = p["fault_kind"]
    if kind in ("stop", "two_stops", "silent", "bias", *ZOO_KINDS):
        first: dict[str, Any] = {
            "robot": p["faulty_robot"],
            "kind": "stop" if kind == "two_stops" else kind,
            "t": p["fault_t"],
        }
        if kind in ("bias", "sensor_bias", "sensor_drift"):  # a random direction
            a = p["bias_angle"]
            m = p["bias_magnitude"] / (10.0 if kind == "sensor_drift" else 1.0)
            first["value"] = [m * float(np.cos(a)), m * float(np.sin(a))]
        if kind == "bias":
            first["time_constant"] = 0.45
        elif kind == "loss_of_effectiveness":
            first["value"] = p["remaining_gain"]
        elif kind == "intermittent":
            first.update(period=p["fault_period"], duty=0.5)
        d["faults"] = [first]
        if kind in ("two_stops", "silent"):  # then a stop (of the silent robot itself)
            d["faults"].append({"robot": p["second_robot"], "kind": "stop", "t": p["second_t"]})
    elif kind == "none":
        d["faults"] = []
    noise = d.setdefault("noise", {})
    for key in ("eta_bar", "xi_bar"):
        if key in p:
            noise[key] = p[key]
    if "method" in p:  # the method's blocks over the scenario's own (its [fdir] over [fdir])
        method = dict(spec.vary["methods"][p["method"]])
        fdir = method.pop("fdir", None)
        _merge(d.setdefault("onboard", {}), method)
        if isinstance(fdir, dict):
            _merge(d.setdefault("fdir", {}), fdir)
    dotted = {key: p[key] for key in spec.vary.get("scenario_keys", {}) if key in p}
    if dotted:
        d = scenario_mod.apply_overrides(
            d, dotted, where=where or f"{spec.source} (run {p['run']}, [vary])"
        )
    return d


def scenario_for(spec: Spec, p: dict[str, Any]) -> scenario_mod.Scenario:
    """The validated scenario of one run (errors name the campaign spec and the run)."""
    return scenario_mod.from_dict(scenario_dict(spec, p), source=f"{spec.source} (run {p['run']})")
