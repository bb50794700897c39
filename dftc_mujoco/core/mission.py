"""The global mission: desired centroid path, formation, and the task map σ = J x.

σ = [σ₁; σ₂] with σ₁ the centroid (eq. 12) and σ₂ the chain of differences
x_{k+1} − x_k (eq. 13). J is square and invertible (docs/notes.md, 11), so J† = J⁻¹,
and both J x and J⁻¹ σ are computed in O(N n) without forming J.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

ARENA_HALF = 50.0  # [m] the floor is 100 m x 100 m (models/arena.xml): every mission is on it

# --------------------------------------------------------------------------- the types


@dataclass(frozen=True, eq=False)
class CentroidPath:
    """Piecewise-linear waypoints, rounded at the corners, travelled at ``speed``."""

    waypoints: np.ndarray  # (W, 2)
    speed: float
    corner_radius: float = 0.3
    ramp_time: float = 2.0
    # fly a speed that leaves the drives no room more slowly (governed_speed); false: as given
    governor: bool = True


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


# --------------------------------------------------------------------------- task map


def task_matrix(n_robots: int, n_dim: int = 2) -> np.ndarray:
    """The dense J of eq. 11 (for tests and documentation; the loop never forms it)."""
    j1 = np.kron(np.ones((1, n_robots)) / n_robots, np.eye(n_dim))  # eq. 12
    d = np.zeros((n_robots - 1, n_robots))
    d[np.arange(n_robots - 1), np.arange(n_robots - 1)] = -1.0
    d[np.arange(n_robots - 1), np.arange(1, n_robots)] = 1.0
    j2 = np.kron(d, np.eye(n_dim))  # eq. 13
    return np.vstack([j1, j2])


def task_map(x: np.ndarray) -> np.ndarray:
    """σ = J x (eqs. 11-13) for positions ``x`` of shape (..., N, n); returns (..., N, n).

    Row 0 is the centroid σ₁, rows 1..N-1 the formation differences σ₂.
    """
    sigma = np.empty_like(x)
    sigma[..., 0, :] = x.mean(axis=-2)
    sigma[..., 1:, :] = np.diff(x, axis=-2)
    return sigma


def task_errors(x: np.ndarray, x_d: np.ndarray, active: np.ndarray) -> np.ndarray:
    """‖σ₁ − σ₁,d‖ and ‖σ₂ − σ₂,d‖ (T, 2) of the members over logged samples (eqs. 9-12).

    ``x``, ``x_d`` (T, N, 2) true and desired positions, ``active`` (T, N) membership.
    """
    out = np.full((len(x), 2), np.nan)
    for r in range(len(x)):
        act = active[r]
        if not act.any():
            continue
        err = task_map(x[r, act] - x_d[r, act])  # σ − σ_d = J (x − x_d)
        out[r] = (np.sqrt(err[0] @ err[0]), np.sqrt(np.sum(err[1:] ** 2)))
    return out


def task_inverse(sigma: np.ndarray) -> np.ndarray:
    """x = J⁻¹ σ, the inverse of :func:`task_map`, in O(N n)."""
    chain = np.zeros_like(sigma)
    chain[..., 1:, :] = np.cumsum(sigma[..., 1:, :], axis=-2)  # x_k - x_1
    return chain - chain.mean(axis=-2, keepdims=True) + sigma[..., :1, :]


# --------------------------------------------------------------------------- formation


def polygon_offsets(n_robots: int, side: float, rotation_deg: float = 0.0) -> np.ndarray:
    """Vertices (N, 2) of a regular N-gon of the given side, centred on the origin.

    Robot k sits at vertex k, counter-clockwise; with rotation 0 and N = 4 the
    square is axis-aligned. For N = 2 the "polygon" is a segment of length ``side``.
    """
    if n_robots == 1:
        return np.zeros((1, 2))
    radius = side / (2.0 * np.sin(np.pi / n_robots)) if n_robots > 2 else side / 2.0
    start = -np.pi / 2 - np.pi / n_robots + np.deg2rad(rotation_deg)
    ang = start + 2.0 * np.pi * np.arange(n_robots) / n_robots
    return radius * np.stack([np.cos(ang), np.sin(ang)], axis=1)


def grid_offsets(n_robots: int, spacing: float, rotation_deg: float = 0.0) -> np.ndarray:
    """Row-major square-ish grid (ceil(√N) columns) of the given spacing, centred."""
    cols = int(np.ceil(np.sqrt(n_robots)))
    k = np.arange(n_robots)
    pts = np.stack([k % cols, -(k // cols)], axis=1) * spacing
    return _rotate(pts - pts.mean(axis=0), rotation_deg)


def line_offsets(n_robots: int, spacing: float, rotation_deg: float = 0.0) -> np.ndarray:
    """Robots on a line across the x axis (a rank), ``spacing`` apart, centred."""
    pts = np.stack([np.zeros(n_robots), -np.arange(n_robots) * spacing], axis=1)
    return _rotate(pts - pts.mean(axis=0), rotation_deg)


def _rotate(pts: np.ndarray, deg: float) -> np.ndarray:
    c, s = np.cos(np.deg2rad(deg)), np.sin(np.deg2rad(deg))
    return pts @ np.array([[c, s], [-s, c]])


def formation_offsets(formation: Formation, n_robots: int) -> np.ndarray:
    """Offsets (N, 2) from the centroid for the scenario's formation shape."""
    if formation.shape == "polygon":
        return polygon_offsets(n_robots, formation.side, formation.rotation)
    if formation.shape == "grid":
        return grid_offsets(n_robots, formation.side, formation.rotation)
    if formation.shape == "line":
        return line_offsets(n_robots, formation.side, formation.rotation)
    raise ValueError(f"unknown formation shape {formation.shape!r}")


# --------------------------------------------------------------------------- centroid path


@dataclass(frozen=True)
class PathTable:
    """Desired centroid position and velocity sampled at every control instant."""

    t: np.ndarray  # (K,)
    position: np.ndarray  # (K, 2)
    velocity: np.ndarray  # (K, 2)

    def at(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        """Position and velocity at control step ``k`` (clamped to the table)."""
        k = min(k, len(self.t) - 1)
        return self.position[k], self.velocity[k]


def slot_spacing(formation: Formation, n_robots: int) -> float:
    """The smallest distance between two slots of ``formation`` [m] (inf for one robot)."""
    if n_robots <= 1:
        return float("inf")
    from scipy.spatial import cKDTree  # a k-d tree, not the N × N distances (80 ms at 1000)

    offsets = formation_offsets(formation, n_robots)
    tree = cKDTree(offsets)
    nearest = tree.query(offsets, k=2)[0][:, 1].min()
    # the pairs that near, measured as np.hypot measures them (the tree rounds its own way)
    pairs = tree.query_pairs(nearest * (1 + 1e-9), output_type="ndarray")
    return float(np.hypot(*(offsets[pairs[:, 0]] - offsets[pairs[:, 1]]).T).min())


def _filleted_path(waypoints: np.ndarray, corner_radius: float):
    """Polyline with circular fillets at interior corners: tangent-continuous.

    Returns a list of segments, each ("line", p0, p1) or ("arc", centre, r, a0, da),
    and the total length.
    """
    pts = np.asarray(waypoints, float)
    keep = [pts[0]]
    for p in pts[1:]:
        if np.linalg.norm(p - keep[-1]) > 1e-9:
            keep.append(p)
    pts = np.array(keep)
    if len(pts) == 1:
        return [("line", pts[0], pts[0])], 0.0
    seg_len = np.linalg.norm(np.diff(pts, axis=0), axis=1)
    # Tangent length of each corner fillet, limited to half the adjacent segments.
    segments: list[tuple[Any, ...]] = []
    cursor = pts[0]
    for c in range(1, len(pts) - 1):
        a = (pts[c] - pts[c - 1]) / seg_len[c - 1]
        b = (pts[c + 1] - pts[c]) / seg_len[c]
        turn = np.arctan2(a[0] * b[1] - a[1] * b[0], a @ b)
        if abs(turn) < 1e-9 or corner_radius <= 0:
            continue
        tan_len = min(corner_radius * np.tan(abs(turn) / 2), seg_len[c - 1] / 2, seg_len[c] / 2)
        r = tan_len / np.tan(abs(turn) / 2)
        p_in = pts[c] - a * tan_len
        p_out = pts[c] + b * tan_len
        segments.append(("line", cursor, p_in))
        normal = np.array([-a[1], a[0]]) * np.sign(turn)  # towards the centre
        centre = p_in + normal * r
        a0 = np.arctan2(*(p_in - centre)[::-1])
        segments.append(("arc", centre, r, a0, turn))
        cursor = p_out
    segments.append(("line", cursor, pts[-1]))
    length = sum(
        np.linalg.norm(s[2] - s[1]) if s[0] == "line" else s[2] * abs(s[4]) for s in segments
    )
    return segments, float(length)


def _eval_path(segments, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Position and unit tangent at arc lengths ``s`` (vectorised over s)."""
    pos = np.zeros((len(s), 2))
    tan = np.zeros((len(s), 2))
    tan[:, 0] = 1.0
    offset = 0.0
    remaining = np.ones(len(s), bool)
    for k, seg in enumerate(segments):
        if seg[0] == "line":
            p0, p1 = seg[1], seg[2]
            seg_l = float(np.linalg.norm(p1 - p0))
            direction = (p1 - p0) / seg_l if seg_l > 0 else np.array([1.0, 0.0])
        else:
            _, centre, r, a0, da = seg
            seg_l = r * abs(da)
        last = k == len(segments) - 1
        m = remaining & ((s <= offset + seg_l) | last)
        u = np.clip(s[m] - offset, 0.0, seg_l)
        if seg[0] == "line":
            pos[m] = p0 + np.outer(u, direction)
            tan[m] = direction
        else:
            ang = a0 + np.sign(da) * u / r
            pos[m] = centre + r * np.stack([np.cos(ang), np.sin(ang)], axis=1)
            tan[m] = np.sign(da) * np.stack([-np.sin(ang), np.cos(ang)], axis=1)
        remaining &= ~m
        offset += seg_l
    return pos, tan


#: the share of the robots' applied range the path governor lets the path's speed take; the
#: rest is for the formation's corrections and the supervisor's avoidance (beyond the applied
#: range they are saturated: slower, not a broken premise)
GOVERNED_SHARE = 0.95


def fastest_path(applied: float, command: float) -> float:
    """[m/s] The fastest path speed a team flies as given: :data:`GOVERNED_SHARE` of its
    drives' applied range ``applied`` (per axis), within the command range ``command``."""
    return GOVERNED_SHARE * min(applied, command)


def governed_speed(speed: float, applied: float, command: float) -> float | None:
    """The path speed a team flies when ``speed`` [m/s], inside its drives' command range
    ``command``, leaves them no room: the robots' commands stay within their applied range
    ``applied`` (per axis: the command range less the compensation's headroom) only if the
    path takes at most :data:`GOVERNED_SHARE` of it. None when ``speed`` fits, when no range
    is known, or beyond the command range (a path no robot of the team can follow: the
    checks refuse it)."""
    top = fastest_path(applied, command)
    if not math.isfinite(top) or speed <= top or speed > command:
        return None
    return top


def centroid_table(path: CentroidPath, duration: float, dt: float) -> PathTable:
    """Sample the desired centroid at t = 0, dt, ..., duration.

    The speed rises smoothly from 0 over ``ramp_time`` and, near the last
    waypoint, falls as (L − s)/ramp_time, so the desired velocity is continuous
    everywhere; the fillets make the direction continuous at the corners.
    """
    segments, length = _filleted_path(path.waypoints, path.corner_radius)
    k = round(duration / dt) + 1
    t = np.arange(k) * dt
    # Integrate ds/dt = v * ramp(t) * min(1, (L - s)/(v T_r)) (scipy, dense output).
    from scipy.integrate import solve_ivp

    v, tr = path.speed, path.ramp_time

    def rate(tt: float, ss: np.ndarray) -> np.ndarray:
        ramp = 1.0 if tt >= tr else 0.5 - 0.5 * np.cos(np.pi * tt / tr)
        brake = np.clip((length - ss) / (v * tr), 0.0, 1.0)
        return v * ramp * brake

    if length > 0 and duration > 0:
        sol = solve_ivp(
            rate, (0.0, t[-1]), [0.0], dense_output=True, max_step=tr, rtol=1e-8, atol=1e-10
        )
        s = np.clip(sol.sol(t)[0], 0.0, length)
    else:
        s = np.zeros(k)
    ramp = np.where(t >= tr, 1.0, 0.5 - 0.5 * np.cos(np.pi * np.minimum(t, tr) / tr))
    sdot = v * ramp * np.clip((length - s) / (v * tr), 0.0, 1.0)
    pos, tan = _eval_path(segments, s)
    pos.setflags(write=False)
    vel = tan * sdot[:, None]
    vel.setflags(write=False)
    return PathTable(t, pos, vel)


# --------------------------------------------------------------------------- re-planning


def replan(formation: Formation, old: np.ndarray) -> np.ndarray:
    """The same formation for the robots left (rows of ``old``), assigned to minimise travel.

    A polygon may also rotate (:func:`replan_polygon`); a grid or a line keeps
    its orientation and only the robot-to-slot assignment is optimised.
    """
    from scipy.optimize import linear_sum_assignment

    if formation.shape == "polygon":
        return replan_polygon(old, formation.side)
    target = formation_offsets(formation, len(old))
    cost = ((old[:, None, :] - target[None, :, :]) ** 2).sum(axis=2)
    _, cols = linear_sum_assignment(cost)
    return target[cols]


def replan_polygon(old: np.ndarray, side: float, n_angles: int = 90) -> np.ndarray:
    """A regular polygon with one vertex per row of ``old``, assigned to minimise travel.

    ``old`` (M, 2) are the remaining robots' current formation offsets. The
    new polygon keeps ``side``; its rotation (searched on a grid over one
    symmetry period) and the robot-to-vertex assignment (Hungarian method)
    minimise Σ‖newᵢ − oldᵢ‖². Every robot computes the same plan from the same
    common knowledge (old offsets, who left), so the plan needs no messages.
    """
    from scipy.optimize import linear_sum_assignment

    m = len(old)
    base = polygon_offsets(m, side)
    best_cost, best = np.inf, base
    for ang in np.linspace(0.0, 2.0 * np.pi / max(m, 1), n_angles, endpoint=False):
        c, s = np.cos(ang), np.sin(ang)
        verts = base @ np.array([[c, s], [-s, c]])
        cost = ((old[:, None, :] - verts[None, :, :]) ** 2).sum(axis=2)
        rows, cols = linear_sum_assignment(cost)
        total = cost[rows, cols].sum()
        if total < best_cost:
            best_cost, best = total, verts[cols]
    return best


@dataclass(frozen=True)
class FormationPlan:
    """Formation offsets moving from ``start`` to ``target`` over ``blend`` s from ``t0``.

    The blend is the quintic 10τ³ − 15τ⁴ + 6τ⁵: offsets, their rate and
    acceleration are continuous, so re-planning makes no command jump (docs/notes.md, 12).
    """

    start: np.ndarray  # (M, 2)
    target: np.ndarray  # (M, 2)
    t0: float = 0.0
    blend: float = 0.0
    _still: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "_still", np.zeros_like(self.target))  # the rate once settled

    @classmethod
    def fixed(cls, offsets: np.ndarray) -> FormationPlan:
        return cls(offsets, offsets)

    def at(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Offsets (M, 2) and their time derivative at ``t`` (shared arrays: do not modify)."""
        if self.blend <= 0 or t >= self.t0 + self.blend:
            return self.target, self._still
        tau = max(0.0, (t - self.t0) / self.blend)
        s = tau**3 * (10 - 15 * tau + 6 * tau**2)
        ds = 30 * tau**2 * (1 - tau) ** 2 / self.blend
        delta = self.target - self.start
        return self.start + s * delta, ds * delta
