"""Checks before a run: refuse what cannot be meaningful, warn about what may not be.

Each finding is one line naming the scenario file and key, what is wrong and what to
change. A *refusal* (:class:`~dftc_mujoco.errors.ScenarioError`, exit 2) is for a
set-up whose run would say nothing (hulls that overlap in the formation, a robot that
starts inside a cylinder, a mission faster than the actuators, a fault no actuator could
produce, more memory than the machine has); a *warning* (an event at t = 0, listed in
``summary.json``) is for one that can run but deserves a look (a bias the actuators
cannot compensate, distances raised for a big robot, options of the robot's MJCF that
the arena overrides).
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

from ..core.mission import ARENA_HALF, fastest_path, formation_offsets
from ..errors import ScenarioError
from ..scenario import Scenario

CLEARANCE = 0.02  # least gap kept between a robot's hull and a cylinder or robot [m]
FAULT_CAP = 10.0  # a bias beyond this many command ranges has no physical meaning
MEMORY_FRACTION = 0.8  # refuse a run estimated to need more of the available memory


@dataclass
class Findings:
    """Refusals and warnings of the checks, each one line."""

    refusals: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)

    def raise_refusals(self) -> None:
        """Raise one ScenarioError holding every refusal (one line each)."""
        if self.refusals:
            raise ScenarioError("\n".join(self.refusals))


# --------------------------------------------------------------------------- memory


def memory_estimate(s: Scenario) -> dict[str, int]:
    """Bytes a run of ``s`` will hold at its peak, by part (an estimate, on the high side)."""
    from ..core.record import MATRIX_LOG_BUDGET

    n = s.team.robots
    dt = s.physics.control_period
    periods = s.duration / dt + 2
    rows = periods / max(1, round(1.0 / (s.physics.log_rate * dt))) + 2
    per_row = 200 * n  # positions, inputs, estimates, poses, flags... in float64
    nn = 16 * n * n  # float32 estimates (2), residuals, thresholds
    if s.physics.matrix_log_rate == "auto":
        matrix = min(rows * nn, MATRIX_LOG_BUDGET + nn)
    else:
        matrix = rows * nn / max(1.0, s.physics.log_rate / float(s.physics.matrix_log_rate))
    parts = {
        # the log, its derived fields and the copies written to log.npz
        "log": 2 * (rows * per_row + matrix),
        # every robot's estimate of the whole team: ~15 N x N x 2 float64 arrays
        "team": 15 * 16 * n * n,
        "path": 32 * periods,  # the desired centroid at every period
        "physics": 400_000 * n + 300 * 2**20,  # MuJoCo model and data, interpreter
    }
    if not s.network.ideal:  # each link's ring of messages in flight, a slot per period
        from .network import timing

        links = len(s.team.graph.edges)
        parts["network"] = 2 * 8 * links * (timing(s.network, dt).latency + 2.0)
    return {k: int(min(float(v), 2.0**62)) for k, v in parts.items()}  # no overflow


def available_memory() -> int:
    """Bytes of memory available to a new allocation (MemAvailable on Linux)."""
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    try:
        return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):
        return 2**62


def check_memory(s: Scenario, available: int | None = None) -> None:
    """Refuse a run that would need more memory than the machine has (one line, with the
    estimate and the knobs that reduce it), before anything big is allocated."""
    parts = memory_estimate(s)
    total = sum(parts.values())
    free = available_memory() if available is None else available
    if total <= MEMORY_FRACTION * free:
        return
    gb = 2**30
    big = max(parts, key=parts.get)  # type: ignore[arg-type]
    knob = {
        "log": "duration, physics.log_rate or physics.matrix_log_rate",
        "team": "team.robots (every robot estimates the whole team: memory grows as N²)",
        "path": "duration",
        "physics": "team.robots",
        "network": "network.latency (each link keeps a slot per control period of latency: "
        "a latency in s, 20 ms is 0.02)",
    }[big]
    if big == "network":
        keys = "network.latency"
        what = f"{len(s.team.graph.edges)} links, a latency of {s.network.latency:g} s"
    else:
        keys = "duration, team.robots, physics.log_rate"
        what = f"{s.team.robots} robots, {s.duration:g} s at {s.physics.log_rate:g} Hz"
    raise ScenarioError(
        f"{s.source}: {keys}: this run needs about {total / gb:.1f} GB ({big} "
        f"{parts[big] / gb:.1f} GB: {what}) and {free / gb:.1f} GB are available; reduce {knob}"
    )


# --------------------------------------------------------------------------- the set-up


def _formation_room(
    s: Scenario,
    offsets: np.ndarray,
    reach: float,
    name: str,
    contacts: bool,
    finding: Callable[..., None],
) -> None:
    """The formation (its slots' ``offsets``), and the one re-planned without a robot: hulls
    must not overlap."""
    need = 2 * reach + CLEARANCE
    n = s.team.robots
    for m in (n, n - 1) if s.fdir.enabled and n > 2 else (n,):
        slots = offsets if m == n else formation_offsets(s.mission.formation, m)
        spacing = _closest_pair(slots)
        if spacing < need:
            which = "the formation" if m == n else f"the re-planned formation of {m} robots"
            # the scale that makes the room, of the document as written (it may be scaled)
            scale = math.ceil(10 * s.scale * need / max(spacing, 1e-9)) / 10
            finding(
                "mission.formation.side",
                f"{which} puts two slots {spacing:.3f} m apart, but two {name} robots need "
                f"{need:.3f} m (footprint radius {reach:.3f} m each, + {CLEARANCE:g} m): use "
                f"side >= {s.mission.formation.side * need / max(spacing, 1e-9):.3f}, or "
                f"mission.scale = {scale:g} (the "
                "whole mission that much bigger: path, cylinders, starts, times)"
                + ("" if contacts else " (robot contacts are off: hulls will pass through)"),
                refuse=contacts,
            )
            break


def _starts(
    s: Scenario,
    reach: float,
    safe: np.ndarray,
    footprints: np.ndarray | None,
    contacts: bool,
    finding: Callable[..., None],
) -> None:
    """Where the robots start: not inside a cylinder, not inside each other."""
    x0 = np.asarray(s.team.initial_positions, float)
    own = np.full(len(x0), reach) if footprints is None else np.asarray(footprints, float)
    for k, ob in enumerate(s.obstacles):
        gap = np.linalg.norm(x0 - ob.position, axis=1) - ob.radius - own
        for i in np.flatnonzero(gap < 0):
            finding(
                "team.initial_positions",
                f"robot {i + 1} starts with its hull {-gap[i]:.3f} m inside cylinder {k + 1} "
                f"(its footprint radius is {own[i]:.3f} m); move it or the cylinder",
                refuse=True,
            )
        inside = np.flatnonzero((gap >= 0) & (np.linalg.norm(x0 - ob.position, axis=1) < safe[k]))
        for i in inside:
            finding(
                "team.initial_positions",
                f"robot {i + 1} starts inside cylinder {k + 1}'s safe distance "
                f"({safe[k]:.3f} m): its first command is to get out",
                refuse=False,
            )
    near = sorted(cKDTree(x0).query_pairs(2 * reach)) if reach > 0 else []
    pairs = [(i, j) for i, j in near if np.linalg.norm(x0[i] - x0[j]) < own[i] + own[j]]
    for i, j in pairs[:3]:
        d = float(np.linalg.norm(x0[i] - x0[j]))
        finding(
            "team.initial_positions",
            f"robots {i + 1} and {j + 1} start {d:.3f} m apart: their hulls overlap "
            f"(footprint radii {own[i]:.3f} m and {own[j]:.3f} m)"
            + ("" if contacts else " (robot contacts are off: they pass through)"),
            refuse=contacts,
        )
    if len(pairs) > 3:
        finding("team.initial_positions", f"... {len(pairs) - 3} more overlapping pairs", contacts)


def _fault_sizes(
    s: Scenario, name: str, command_limit: float, finding: Callable[..., None]
) -> None:
    """Biases and drifts against the command range: beyond any actuator offset (refused), or
    beyond what the compensation can cancel while the team moves (warned)."""
    speed = s.mission.centroid.speed
    cap = FAULT_CAP * (command_limit if math.isfinite(command_limit) else max(1.0, speed))
    for k, f in enumerate(s.faults):
        if f.kind == "drift":  # a bias growing at value [m/s²]: as big as a bias, at its end
            rate = float(np.abs(f.value).max())
            until = min(s.duration, f.end)
            peak = rate * max(until - f.t, 0.0)
            if peak > cap:
                finding(
                    f"faults[{k + 1}].value",
                    f"a drift of {rate:g} m/s² on robot {f.robot + 1} grows to a bias of "
                    f"{peak:g} m/s by t = {until:g} s, {peak / cap * FAULT_CAP:.0f} times the "
                    f"{name} robots' command range (±{command_limit:.3g} m/s): no actuator "
                    f"offset produces that; expected at most {cap / max(until - f.t, 1e-12):.3g} "
                    "m/s² (a drift is in m/s per second), or an end",
                    refuse=True,
                )
            continue
        if f.kind != "bias":
            continue
        size = float(np.abs(f.value).max())
        key = f"faults[{k + 1}].value"
        if size > cap:
            finding(
                key,
                f"a bias of {size:g} m/s is {size / cap * FAULT_CAP:.0f} times the "
                f"{name} robots' command range (±{command_limit:.3g} m/s): no actuator offset "
                f"produces that; expected at most {cap:g} m/s",
                refuse=True,
            )
        elif size + speed > command_limit:
            finding(
                key,
                f"a bias of {size:g} m/s on robot {f.robot + 1} cannot be compensated within "
                f"the ±{command_limit:.3g} m/s command range while the team moves at "
                f"{speed:g} m/s: it acts as an unrecoverable fault",
                refuse=False,
            )


def preflight(
    s: Scenario,
    robot,
    command_limit: float,
    safe: np.ndarray,
    activation: np.ndarray,
    path: np.ndarray,
    path_dt: float,
    input_limit: float = math.inf,
    xi_bar: float = 0.0,
    G: np.ndarray | None = None,
    footprints: np.ndarray | None = None,
) -> Findings:
    """Check scenario ``s`` with robot model ``robot`` (footprint, drive) whose planar
    command range is ``command_limit`` per axis; ``safe`` and ``activation`` are the
    cylinders' distances after they were raised for the robot's footprint; ``path`` (T, 2)
    the desired centroid every ``path_dt`` seconds; ``input_limit`` the applied input's
    range per axis (``assembly.input_limit``); ``xi_bar`` and ``G`` the run's ξ̄ and G (the
    scenario's or the robot's); ``footprints`` (N,) each robot's own footprint radius (a
    mixed team: the starts are checked robot by robot; None: the model's for every one)."""
    out = Findings()
    src = s.source
    reach = robot.footprint_radius
    name = robot.name
    contacts = s.physics.robot_contacts

    def finding(key: str, message: str, refuse: bool) -> None:
        (out.refusals if refuse else out.warnings).append(f"{src}: {key}: {message}")

    periods = s.duration / s.physics.control_period  # the run is a whole number of them
    if abs(periods - round(periods)) > 1e-6:
        finding(
            "duration",
            f"{s.duration:g} s is not a whole number of control periods "
            f"({s.physics.control_period:g} s): the run ends at "
            f"{round(periods) * s.physics.control_period:g} s",
            False,
        )
    offsets = formation_offsets(s.mission.formation, s.team.robots)  # about the centroid
    _formation_room(s, offsets, reach, name, contacts, finding)
    _starts(s, reach, safe, footprints, contacts, finding)
    # the cylinders' distances, raised for a big robot
    for k, ob in enumerate(s.obstacles):
        if safe[k] > ob.safe_distance + 1e-12:
            finding(
                f"obstacles[{k + 1}].safe_distance",
                f"raised from {ob.safe_distance:g} to {safe[k]:.3f} m for the {name} footprint "
                f"({reach:.3f} m + {CLEARANCE:g} m), and activation_distance from "
                f"{ob.activation_distance:g} to {activation[k]:.3f} m with it",
                refuse=False,
            )
    # room to avoid a cylinder without running into a teammate (no teammate avoidance)
    # every formation slot's distance to every cylinder along the path (T, N, O)
    dist = _slot_distances(s, path, offsets) if s.obstacles else None
    squeeze = _squeeze(offsets, safe, reach, dist, path_dt)
    if squeeze is not None:
        k, t, depth, room = squeeze
        finding(
            f"obstacles[{k + 1}]",
            f"near t = {t:.0f} s a formation slot passes {depth:.3f} m inside cylinder "
            f"{k + 1}'s safe distance, but two {name} robots have only {max(room, 0):.3f} m "
            "between their hulls in the formation: the robot that avoids it may run into a "
            "teammate (the paper's controllers do not avoid teammates); a formation that "
            "straddles the cylinder or passes it with more room avoids this",
            refuse=False,
        )
    # the command range against the mission and the faults
    if (speed := s.mission.centroid.speed) > command_limit:
        finding(
            "mission.centroid.speed",
            f"{speed:g} m/s is beyond the {name} robots' command range of "
            f"±{command_limit:.3g} m/s per axis: the team cannot follow the path"
            f"{_flyable(input_limit, command_limit)}",
            refuse=True,
        )
    elif speed > input_limit:
        finding(
            "mission.centroid.speed",
            f"{speed:g} m/s is beyond the {name} robots' applied range of ±{input_limit:.3g} "
            f"m/s per axis (the command range ±{command_limit:.3g} m/s less the compensation's "
            "headroom Φ̄), flown as given (mission.centroid.governor = false): the robots' "
            "commands saturate on the path, where no threshold rule's guarantee holds (its "
            "premise 'saturation'); set the governor on to fly it slower, or lower the speed",
            refuse=False,
        )
    _fault_sizes(s, name, command_limit, finding)
    _magnitudes(s, offsets, finding, name, command_limit, xi_bar, G)
    _sightings(s, finding)
    _walls(s, finding, name, safe, reach, dist, path_dt)
    # the path stays on the floor
    w = np.asarray(s.mission.centroid.waypoints)
    far = np.abs(w).max() + _radius(offsets) + reach
    if far > ARENA_HALF:
        finding(
            "mission.centroid.waypoints",
            f"the team would reach {far:.1f} m from the origin; the arena's floor ends at "
            f"±{ARENA_HALF:g} m",
            refuse=True,
        )
    return out


#: [s] a run expected to take longer than this (wall time) is announced before it starts
LONG_RUN = 600.0
#: [s] wall time of one physics step per robot, and per step (this machine, measured with
#: benchmarks/bench_scale.py: 2 ms for 5 steps of 1000 robots; ~10 µs a step at N = 4)
STEP_COST = (0.4e-6, 5e-6)


def run_time(s: Scenario) -> float:
    """A rough wall time [s] for the physics of ``s`` alone (a lower bound of the run's)."""
    steps = s.duration / s.physics.timestep
    return steps * (STEP_COST[0] * s.team.robots + STEP_COST[1])


def _magnitudes(s, offsets: np.ndarray, finding, name: str, limit: float, xi_bar: float, G) -> None:
    """Numbers that pass their type and sign checks but mean nothing physically: refused or
    warned with the unit the user probably meant (``offsets``: the formation's slots)."""
    if math.isfinite(limit) and xi_bar >= limit:
        finding(
            "noise.xi_bar",
            f"{xi_bar:g} m/s of actuator noise is as large as the {name} robots' whole command "
            f"range (±{limit:.3g} m/s): no fault can be told from it (ξ̄ is in m/s: 5 mm/s is "
            "0.005)",
            refuse=True,
        )
    elif math.isfinite(limit) and xi_bar > 0.2 * limit:
        finding(
            "noise.xi_bar",
            f"{xi_bar:g} m/s of actuator noise is {xi_bar / limit:.0%} of the {name} robots' "
            f"command range (±{limit:.3g} m/s): the thresholds grow with it and a stop may go "
            "undetected (ξ̄ is in m/s: 5 mm/s is 0.005)",
            refuse=False,
        )
    spacing = _closest_pair(offsets)
    if s.noise.eta_bar > 0.5 * spacing:
        finding(
            "noise.eta_bar",
            f"{s.noise.eta_bar:g} m of position noise is more than half the formation's spacing "
            f"({spacing:.3g} m): the robots cannot tell their slots apart (η̄ is in m: 1 mm is "
            "0.001)",
            refuse=s.noise.eta_bar >= spacing,
        )
    h = s.physics.control_period
    kc = float(s.gains.kc)
    if kc * h >= 1.0:  # eq. 15 at period h: e⁺ = (1 − h kc) e, a sign flip from h kc > 1
        finding(
            "gains.kc",
            f"kc = {kc:g} moves each robot {kc * h:.3g} times its formation error per control "
            f"period ({h:g} s): the controller (eq. 15) "
            + (
                "diverges, or chatters against the command range, instead of converging"
                if kc * h >= 2.0
                else "overshoots every period, alternating sides of its slot"
            )
            + f"; expected kc < {1.0 / h:.3g} (kc·control_period < 1; the paper's is 4)",
            refuse=kc * h >= 2.0,
        )
    if s.fdir.enabled and s.fdir.compensate and G is not None:  # the loop closes through ū
        g = float(np.linalg.eigvalsh(np.asarray(G, float)).min())
        k = float(np.linalg.eigvalsh(np.asarray(s.gains.K, float)).max())
        gain = h * (1.0 / g + k)  # eqs. 28-31 at period h: e⁺ = (1 − h(1/G + K)) e + ...
        if h * k >= 2.0:  # K alone: no G makes it stable
            finding(
                "gains.K",
                f"K = {k:g} makes the fault estimator's compensation loop unstable at "
                f"control_period = {h:g} s whatever G is (control_period·K = {h * k:.3g}, "
                f"expected < 2): expected K < {2.0 / h:.3g} (the paper's is 3)",
                refuse=True,
            )
        elif gain >= 2.0:
            need = h / (2.0 - h * k) if h * k < 2.0 else math.inf
            finding(
                "gains.G",
                f"G = {g:g} s makes the fault estimator's compensation loop unstable at "
                f"control_period = {h:g} s (control_period·(1/G + K) = {gain:.3g}, expected < 2): "
                f"φ̂ would grow without bound; expected G > {need:.3g} (the paper's is 0.01)",
                refuse=True,
            )
    d = s.fdir.excluded_safe_distance
    width = 2 * _radius(offsets)
    if s.fdir.enabled and d > max(width, 1.0):
        finding(
            "fdir.excluded_safe_distance",
            f"{d:g} m around an excluded robot is "
            + (
                f"more than the arena's half-width ({ARENA_HALF:g} m): no teammate could ever "
                "get out of it"
                if d > ARENA_HALF
                else f"wider than the whole formation ({width:.3g} m across): at an exclusion "
                "every teammate is inside it at once and turns away"
            )
            + " (a robot's size is a few tenths of a metre)",
            refuse=d > ARENA_HALF,
        )
    wall = run_time(s)
    if wall > LONG_RUN:
        finding(
            "physics.timestep",
            f"{s.duration / s.physics.timestep:.3g} physics steps of {s.team.robots} robots "
            f"(timestep = {s.physics.timestep:g} s): this run will take at least "
            f"{wall / 60:.0f} min of physics alone",
            refuse=False,
        )


def _sightings(s, finding) -> None:
    """A sighting tolerance or range of 0 switches the sighting rule off (legitimate, to
    study the rest): a robot whose radio falls silent and that then stops is never flagged,
    so never excluded. Warned, naming the guarantee lost."""
    if not s.fdir.enabled:
        return
    lost = (
        "a robot whose radio falls silent is no longer judged by what its teammates see: if "
        "it then stops or drifts off, nobody flags it and it is never excluded"
    )
    if s.network.sighting_tolerance == 0:
        finding(
            "network.sighting_tolerance",
            f'0 switches the sighting rule off: {lost} (leave it "auto", half the slots\' '
            "spacing, or give a distance in m)",
            refuse=False,
        )
    elif s.network.sighting_range == 0:
        finding(
            "network.sighting_range",
            f"0 switches the sighting rule off (no robot sees another): {lost}",
            refuse=False,
        )


def _walls(s, finding, name: str, safe: np.ndarray, reach: float, dist, dt: float) -> None:
    """Cylinders too close to pass between (their safe discs overlap, or leave less than a
    robot's width) that the path runs into: the supervisor avoids one obstacle at a time
    (eq. 8), and a robot pushed from one into the next can be trapped or pushed into a
    hull. ``dist``: :func:`_slot_distances`."""
    if len(s.obstacles) < 2:
        return
    centres = np.array([ob.position for ob in s.obstacles])
    gap = np.linalg.norm(centres[:, None] - centres[None], axis=2) - safe[:, None] - safe[None]
    np.fill_diagonal(gap, np.inf)
    joined = gap < 2 * reach + CLEARANCE
    entered = (dist < safe[None, None]).any(axis=(0, 1))  # cylinders some slot runs into
    for k in np.flatnonzero(entered & joined.any(axis=1)):
        group = sorted({int(k), *np.flatnonzero(joined[k]).tolist()})
        t = float(np.flatnonzero((dist[:, :, k] < safe[k]).any(axis=1))[0] * dt)
        finding(
            f"obstacles[{k + 1}]",
            f"cylinders {', '.join(str(g + 1) for g in group)} leave no room for a {name} "
            f"robot between their safe distances, and the formation runs into them near "
            f"t = {t:.0f} s: the supervisor avoids one cylinder at a time (eq. 8), so a robot "
            "can be trapped between them; open a gap of at least "
            f"{2 * reach + CLEARANCE:.3g} m or route the path around them",
            refuse=False,
        )
        return


def _slot_distances(s: Scenario, path: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """(T, N, O): each formation slot (``offsets`` about the centroid) and its distance to
    each cylinder at each sample of the desired centroid ``path`` (T, 2)."""
    slots = path[:, None, :] + offsets[None]
    centres = np.array([ob.position for ob in s.obstacles])
    return np.linalg.norm(slots[:, :, None, :] - centres[None, None], axis=3)


def _squeeze(
    offsets: np.ndarray, safe: np.ndarray, reach: float, dist: np.ndarray | None, dt: float
) -> tuple[int, float, float, float] | None:
    """The deepest pass of a formation slot inside a cylinder's safe distance that is deeper
    than the room between two robots' hulls: (cylinder, time, depth, room), or None.
    ``dist``: :func:`_slot_distances` (None: no cylinders)."""
    if dist is None:
        return None
    room = _closest_pair(offsets) - 2 * reach - CLEARANCE
    depth = (safe[None, None, :] - dist).max(axis=1)  # (T, O)
    t, k = np.unravel_index(int(depth.argmax()), depth.shape)
    if depth[t, k] <= max(room, 0.0):
        return None
    return int(k), t * dt, float(depth[t, k]), float(room)


def _closest_pair(points: np.ndarray) -> float:
    if len(points) < 2:
        return math.inf
    d, _ = cKDTree(points).query(points, k=2)
    return float(d[:, 1].min())


def _radius(points: np.ndarray) -> float:
    return float(np.linalg.norm(points, axis=1).max()) if len(points) else 0.0


def _flyable(input_limit: float, command_limit: float) -> str:
    """The fix for a path too fast for the drives: the fastest speed a team flies as given
    (:func:`.mission.fastest_path`), rounded down to three significant figures."""
    top = fastest_path(input_limit, command_limit)
    if not 0 < top < math.inf:
        return ""
    digits = 2 - math.floor(math.log10(top))
    speed = math.floor(top * 10**digits) / 10**digits
    return (
        f"; a speed of {speed:g} m/s or less leaves its drives room to steer "
        f"(mission.centroid.speed = {speed:g})"
    )
