"""``mission.scale``: one key that scales a mission's geometry and timing.

The stock missions are drawn for the 0.2 m disk. A bigger robot needs the same mission
bigger: every length k times longer (the path, its corner radius, the formation, the start
positions, the cylinders and their distances, the distances kept around an excluded robot
and between teammates, the radio's ranges, the sighting tolerance, the bound ε̄ on the
observers' start error that the threshold rules take, ``fdir.initial_error_bound``) and, at
the same speed, every time of the mission k times later (the duration, the ramp, the
transient, the re-plan, each fault's start and end). Speeds, gains, noise bounds and rates
are unchanged, and so are the robot's own figures (its drift offset ē, calibrated in the
scaled mission). The scaling is applied to the document before
it is read, so that the scenario read is the scaled one (``scenario.toml`` in a run's
folder holds the scaled values, without the key) and every check sees what will run.
Defaults that are lengths or times are written out scaled.
"""

from __future__ import annotations

import copy
import math
from typing import Any

from ..runtime.tomlcheck import describe

#: (table path, key, default) of the lengths a scale multiplies (None: no default)
LENGTHS: tuple[tuple[tuple[str, ...], str, float | None], ...] = (
    (("mission", "centroid"), "corner_radius", 0.3),
    (("mission", "formation"), "side", None),
    (("fdir",), "excluded_safe_distance", 0.35),
    (("fdir",), "excluded_activation_distance", None),
    (("network",), "range", None),
    (("network",), "range_hysteresis", None),
    (("network",), "sighting_range", None),
    (("network",), "sighting_tolerance", None),  # a number: "auto" follows the slots
    (("fdir",), "initial_error_bound", None),  # a number: "auto" follows the start
    (("supervisor",), "teammate_distance", None),  # a number: "auto" follows the footprints
)
#: the same for times
TIMES: tuple[tuple[tuple[str, ...], str, float | None], ...] = (
    ((), "duration", None),
    (("mission",), "transient", None),  # its default depends on the duration: set below
    (("mission", "centroid"), "ramp_time", 2.0),
    (("fdir",), "replan_time", 4.0),
    (("network",), "connectivity_window", None),
)


def _number(v: Any) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)


def _table(data: dict[str, Any], path: tuple[str, ...]) -> dict[str, Any] | None:
    node: Any = data
    for key in path:
        node = node.get(key) if isinstance(node, dict) else None
    return node if isinstance(node, dict) else None


def _times(v: Any, k: float) -> Any:
    """``v`` (a number, or nested lists of numbers) times ``k``; anything else as it is (the
    reader reports it)."""
    if _number(v):
        return v * k
    if isinstance(v, list):
        return [_times(x, k) for x in v]
    return v


def scale_problem(data: dict[str, Any]) -> tuple[float, str | None]:
    """The scale the document asks for (1 when absent) and what is wrong with it, if anything."""
    mission = data.get("mission")
    if not isinstance(mission, dict) or "scale" not in mission:
        return 1.0, None
    k = mission["scale"]
    if not _number(k) or not k > 0:
        return 1.0, f"expected a number > 0 (1: the mission as written), got {describe(k)}"
    return float(k), None


def scaled(data: dict[str, Any], k: float) -> dict[str, Any]:
    """A copy of the document with its lengths and times ``k`` times and no ``mission.scale``."""
    out = copy.deepcopy(data)
    mission = out.get("mission")
    if isinstance(mission, dict):
        mission.pop("scale", None)
    if k == 1.0:
        return out
    duration = out.get("duration")
    if isinstance(mission, dict) and "transient" not in mission and _number(duration):
        assert isinstance(duration, int | float)
        mission["transient"] = min(5.0, duration / 2)  # the reader's default, then scaled
    for group in (LENGTHS, TIMES):
        for path, key, default in group:
            table = _table(out, path) if path else out
            if table is None:
                continue
            if key in table:
                table[key] = _times(table[key], k)
            elif default is not None:
                table[key] = default * k
    centroid = _table(out, ("mission", "centroid"))
    if centroid is not None and "waypoints" in centroid:
        centroid["waypoints"] = _times(centroid["waypoints"], k)
    team = out.get("team")
    if isinstance(team, dict) and "initial_positions" in team:
        start = team["initial_positions"]
        if isinstance(start, dict):  # a layout: its lengths
            for key in ("jitter", "spread", "spacing", "radius"):
                if key in start:
                    start[key] = _times(start[key], k)
            start.setdefault("spread", 5.0 * k)
            start.setdefault("spacing", 0.5 * k)
        else:
            team["initial_positions"] = _times(start, k)
    for o in out.get("obstacles") or []:
        if isinstance(o, dict):
            if "activation_distance" not in o and _number(o.get("safe_distance")):
                o["activation_distance"] = o["safe_distance"] + 0.1  # the reader's default
            for key in ("position", "radius", "safe_distance", "activation_distance"):
                if key in o:
                    o[key] = _times(o[key], k)
    for f in out.get("faults") or []:
        if isinstance(f, dict):
            for key in ("t", "end"):
                if key in f:
                    f[key] = _times(f[key], k)
    return out
