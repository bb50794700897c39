"""Local supervisor: reactive obstacle avoidance in the null space (eqs. 8, 17-18, 22).

Each robot decides alone, from its own measured position and the obstacles
its sensors report, whether to switch from the global input u_g,i to the
avoidance input of eq. 18. Only one behaviour is active at a time (eq. 8); near several
obstacles at once (a crowd of teammates) the avoidance meets all of their primary tasks,
not the nearest one's alone. Teammates are avoided the same way: the teammates its range
sensor sees within their activation distance are obstacles of safe distance
``mate_safe``, so the avoidance enters Δuᵢ like any other and the residuals stay
unaffected (``[supervisor] avoid_teammates``; off, the paper's exact behaviour).
The equation is the compiled :func:`supervise`; :class:`Supervisor` is the
block that calls it.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from .block import Block, TeamConfig

#: from this many teammates on, each robot looks for the ones in reach through a grid of
#: cells as wide as the activation distance (the same choice as looking at all of them)
GRID_FROM = 64

#: the buckets between one row of the grid and the next, modulo the buckets: 2⁶⁴ / φ as a
#: signed integer (rows scattered evenly, whatever the power of two of the buckets)
ROW_STRIDE = -7046029254386353131


@njit(inline="always")
def _cell(cx, cy, cells):  # pragma: no cover - compiled
    """The bucket of the grid cell (cx, cy) among ``cells`` (a power of two): the cells of
    a row in consecutive buckets (the rows scattered), so that three neighbours of a row
    are one range of the sorted teammates."""
    return (np.int64(cx) + np.int64(cy) * ROW_STRIDE) & (cells - 1)


@njit(inline="always")
def _cells(m):  # pragma: no cover - compiled
    """The grid's buckets for ``m`` teammates, the power of two at least 2m, and the length
    of the integers it is sorted in: a key and an order per teammate, the buckets' starts
    (one more) and their fill."""
    cells = 1
    while cells < 2 * m:
        cells *= 2
    return cells, 2 * m + 2 * cells + 1


def grid_work(m: int) -> np.ndarray:
    """The integers :func:`supervise` sorts ``m`` teammates into (a team keeps one, so that
    the period allocates nothing; any other array makes it allocate its own)."""
    return np.zeros(_cells.py_func(m)[1], np.int64)


@njit(cache=True)
def _grid(mates, width, work):  # pragma: no cover - compiled
    """The teammates sorted by the bucket of their cell of side ``width``: bucket h holds
    ``order[start[h]:start[h + 1]]`` (a counting sort; a bucket may hold several cells),
    in ``work`` (:func:`grid_work`) or, if it is too short, in arrays of its own."""
    m = mates.shape[0]
    cells, length = _cells(m)
    if work.shape[0] < length:
        work = np.empty(length, np.int64)
    key = work[:m]
    start = work[m : m + cells + 1]
    fill = work[m + cells + 1 : m + 2 * cells + 1]
    order = work[m + 2 * cells + 1 : length]
    start[:] = 0
    for j in range(m):
        key[j] = _cell(np.floor(mates[j, 0] / width), np.floor(mates[j, 1] / width), cells)
        start[key[j] + 1] += 1
    for h in range(cells):
        start[h + 1] += start[h]
    for h in range(cells):  # a loop, not fill[:] = start[:-1]: numba's slice copy compiles
        fill[h] = start[h]  # its shape-mismatch message, seconds of a cold start
    for j in range(m):
        order[fill[key[j]]] = j
        fill[key[j]] += 1
    return cells, start, order


#: the nearest obstacles (cylinders and teammates) each robot keeps at once as constraints
NEAREST = 8


@njit(inline="always")
def _keep(cons, k, index, margin, h0, h1, barrier, radial, due):  # pragma: no cover - compiled
    """Obstacle ``index`` as one of a robot's constraints (rows of ``cons``: index, margin,
    r̂, barrier, r̂ᵀu_g,i, 1 where eq. 17's primary task is ``due`` for it, else 0), ``k``
    kept so far: at most :data:`NEAREST`, the nearest (by margin; the lower index on a tie,
    the choice of a scan in index order, cylinders first). Returns how many are kept."""
    if k < NEAREST:
        row = k
        k += 1
    else:
        row = 0
        for q in range(1, NEAREST):  # the farthest kept (the higher index on a tie)
            if cons[q, 1] > cons[row, 1] or (
                cons[q, 1] == cons[row, 1] and cons[q, 0] > cons[row, 0]
            ):
                row = q
        if margin > cons[row, 1] or (margin == cons[row, 1] and index > cons[row, 0]):
            return k
    cons[row, 0] = index
    cons[row, 1] = margin
    cons[row, 2] = h0
    cons[row, 3] = h1
    cons[row, 4] = barrier
    cons[row, 5] = radial
    cons[row, 6] = 1.0 if due else 0.0
    return k


@njit(inline="always")
def _mate(
    i, j, x, mates, g0, g1, theta, release, active, n_obs, reach, mate_safe, cons, k
):  # pragma: no cover - compiled
    """Teammate j as robot i's obstacle (eq. 17 with it as the obstacle), kept among its
    constraints when it is in reach (:func:`_keep`), robot i's global input within its
    range being (g0, g1); returns how many are kept."""
    e0 = x[i, 0] - mates[j, 0]
    e1 = x[i, 1] - mates[j, 1]
    d2 = e0 * e0 + e1 * e1
    if j == i or d2 >= reach:
        return k
    dist = np.sqrt(d2)
    h0 = e0 / max(dist, 1e-9)
    h1 = e1 / max(dist, 1e-9)
    radial = h0 * g0 + h1 * g1
    barrier = theta * (mate_safe - dist)
    rel = release if active[i] == n_obs + j else 0.0
    return _keep(
        cons, k, n_obs + j, dist - mate_safe, h0, h1, barrier, radial, radial < barrier + rel
    )


@njit(inline="always")
def _violation(cons, k, u0, u1):  # pragma: no cover - compiled
    """The largest amount by which velocity (u0, u1) falls short of a kept constraint
    r̂ᵀu ≥ θ(d − ‖xᵢ − x_o‖) (0: it meets every one)."""
    worst = 0.0
    for q in range(k):
        worst = max(worst, cons[q, 4] - (cons[q, 2] * u0 + cons[q, 3] * u1))
    return worst


@njit(inline="always")
def _several(cons, k, g0, g1):  # pragma: no cover - compiled
    """Eq. 17's primary task for several obstacles at once: the velocity nearest to u_g,i
    = (g0, g1) that meets every kept constraint r̂ⱼᵀu ≥ θ(dⱼ − ‖xᵢ − xⱼ‖), each the
    half-plane whose boundary eq. 18 puts u on for one obstacle. In the plane the nearest
    such point is u_g,i itself, its projection on one boundary or the corner of two: all
    are tried, the nearest feasible one kept; where none is (a robot pressed from opposite
    sides), the one that falls least short."""
    best0, best1 = g0, g1
    best_v, best_d = _violation(cons, k, g0, g1), 0.0
    for a in range(k):
        h0, h1, b = cons[a, 2], cons[a, 3], cons[a, 4]
        lift = b - (h0 * g0 + h1 * g1)  # ‖r̂‖ = 1: onto r̂ᵀu = b
        c0, c1 = g0 + lift * h0, g1 + lift * h1
        v, d = _violation(cons, k, c0, c1), lift * lift
        if v < best_v - 1e-12 or (abs(v - best_v) <= 1e-12 and d < best_d):
            best0, best1, best_v, best_d = c0, c1, v, d
        for c in range(a + 1, k):
            k0, k1, bc = cons[c, 2], cons[c, 3], cons[c, 4]
            det = h0 * k1 - h1 * k0
            if abs(det) < 1e-9:
                continue
            c0 = (b * k1 - h1 * bc) / det  # r̂ₐᵀu = bₐ and r̂꜀ᵀu = b꜀
            c1 = (h0 * bc - b * k0) / det
            v = _violation(cons, k, c0, c1)
            d = (c0 - g0) ** 2 + (c1 - g1) ** 2
            if v < best_v - 1e-12 or (abs(v - best_v) <= 1e-12 and d < best_d):
                best0, best1, best_v, best_d = c0, c1, v, d
    return best0, best1


@njit(inline="always")
def _nearest(cons, k, due_only):  # pragma: no cover - compiled
    """The row of the nearest kept obstacle (by margin, the lower index on a tie), among
    those whose task is due if ``due_only``; -1: none."""
    near = -1
    for q in range(k):
        if due_only and cons[q, 6] == 0:
            continue
        if (
            near < 0
            or cons[q, 1] < cons[near, 1]
            or (cons[q, 1] == cons[near, 1] and cons[q, 0] < cons[near, 0])
        ):
            near = q
    return near


@njit(inline="always")
def _box(cons, k, g0, g1, limit):  # pragma: no cover - compiled
    """The drive's range ±``limit`` per axis as four more constraints after the ``k`` kept,
    r̂ᵀu ≥ −limit for r̂ = ±e_x, ±e_y; returns how many there are then."""
    for q in range(4):
        h0 = (1.0 if q == 0 else -1.0) if q < 2 else 0.0
        h1 = 0.0 if q < 2 else (1.0 if q == 2 else -1.0)
        cons[k + q, 0] = -1.0
        cons[k + q, 1] = np.inf
        cons[k + q, 2] = h0
        cons[k + q, 3] = h1
        cons[k + q, 4] = -limit
        cons[k + q, 5] = h0 * g0 + h1 * g1
        cons[k + q, 6] = 0.0
    return k + 4


@njit(inline="always")
def _answer(cons, k, g0, g1, ug0, ug1, limit, over):  # pragma: no cover - compiled
    """A robot's behaviour and Δuᵢ from its ``k`` kept constraints: its global input
    u_g,i = (ug0, ug1), (g0, g1) within the range ±``limit`` (scaled by ``over`` > 1 where
    it was beyond). Returns (the obstacle that names the behaviour or -1, Δuᵢ)."""
    due = 0
    for q in range(k):
        if cons[q, 6] > 0:
            due += 1
    near = _nearest(cons, k, True)
    # no task due, but the range, clipping u_g,i axis by axis, would break one
    steer = False
    if due == 0 and over > 1.0 and k > 0:
        c0, c1 = min(max(ug0, -limit), limit), min(max(ug1, -limit), limit)
        if _violation(cons, k, c0, c1) > 1e-12:
            steer = True
            near = _nearest(cons, k, False)
    if due == 0 and not steer:
        return -1, 0.0, 0.0  # u_g,i itself (the drive's range is applied later)
    best = int(cons[near, 0])
    if 0.0 < limit < np.inf:
        k = _box(cons, k, g0, g1, limit)
    du0 = du1 = 0.0
    if due == 1:
        # eq. 18: Jₗ† θ (d − ‖xᵢ − x_o‖) + (I − r̂ r̂ᵀ) u_g,i = u_g,i + r̂ (θ(d − ‖·‖) − r̂ᵀu_g,i)
        du0 = (cons[near, 4] - cons[near, 5]) * cons[near, 2]
        du1 = (cons[near, 4] - cons[near, 5]) * cons[near, 3]
    if due > 1 or steer or _violation(cons, k, g0 + du0, g1 + du1) > 1e-12:
        # several tasks due, the range would break one, or eq. 18 for one would break
        # another's or the range
        v0, v1 = _several(cons, k, g0, g1)
        du0, du1 = v0 - g0, v1 - g1
    return best, du0 + (g0 - ug0), du1 + (g1 - ug1)  # Δu from u_g,i itself


@njit(cache=True)
def supervise(
    x, u_g, obs, safe, act, theta, release, active, u, delta_u, mates, mate_safe, mate_act, work,
    limit,
):  # fmt: skip  # pragma: no cover - compiled
    """Nominal inputs uᵢ (eq. 8) and Δuᵢ = uᵢ − u_g,i (eq. 22) into ``u``, ``delta_u`` (M, n).

    ``x`` (M, n) are the robots' own measured positions, ``obs`` (O, n) the
    sensed obstacle centres with safe distances d (O,) and activation
    distances (O,); ``mates`` (M, n) where robot i's range sensor sees its teammates
    (row i: itself, skipped), avoided within ``mate_act`` at safe distance
    ``mate_safe`` (0: not avoided); ``active[i]`` (updated) is the obstacle robot i
    avoids (O + j for teammate j; the nearest when it avoids several) or -1; ``work``:
    the grid's integers (:func:`grid_work`); ``limit``: the drive's range per axis (inf:
    none). Returns True when some robot switched behaviour.

    A robot judges u_g,i as its drive can apply it: scaled into the range, its direction
    kept (clipped axis by axis it could point straight at an obstacle the input itself
    passes by); an avoiding robot's input keeps to the range (a velocity clipped axis by
    axis afterwards may head into the obstacle it avoids); with no task due uᵢ = u_g,i,
    which the drive's range limits later.

    Within an obstacle's activation distance avoidance switches on when the
    global input would approach it faster than eq. 17's primary task allows,
    r̂ᵀu_g,i < θ(d − ‖xᵢ − x_o‖), and off when r̂ᵀu_g,i exceeds that by
    ``release``; at the switch eq. 18 and u_g,i coincide (docs/notes.md, 12). With one
    such obstacle uᵢ is eq. 18's, unless eq. 18 would break the primary task of another
    obstacle in reach (a robot between two teammates, which u_g,i moves away from one and
    towards the other); then, as with several obstacles due at once (a crowd of
    teammates), uᵢ is the velocity nearest u_g,i that meets the primary task of every
    obstacle in reach (:func:`_several`).
    """
    changed = False
    grid = mate_safe > 0.0 and mates.shape[0] >= GRID_FROM
    if grid:
        cells, start, order = _grid(mates, mate_act, work)
    else:  # no grid: nothing reads them
        cells, start, order = 1, work[:0], work[:0]
    # a robot's constraints (index, margin, r̂, barrier, r̂ᵀu, due): the nearest obstacles,
    # then, where avoidance is due, the drive's range ±limit per axis as four more
    cons = np.empty((NEAREST + 4, 7))
    box = 0.0 < limit < np.inf
    for i in range(x.shape[0]):
        # u_g,i within the drive's range, its direction kept
        g0, g1 = u_g[i, 0], u_g[i, 1]
        over = max(abs(g0), abs(g1)) / limit if box else 0.0
        if over > 1.0:
            g0, g1 = g0 / over, g1 / over
        k = 0
        for o in range(obs.shape[0]):
            e0 = x[i, 0] - obs[o, 0]
            e1 = x[i, 1] - obs[o, 1]
            dist = np.sqrt(e0 * e0 + e1 * e1)
            if dist >= act[o]:
                continue
            h0 = e0 / max(dist, 1e-9)  # r̂: obstacle-to-robot unit vector, Jₗ = r̂ᵀ
            h1 = e1 / max(dist, 1e-9)
            radial = h0 * g0 + h1 * g1  # r̂ᵀ u_g,i
            barrier = theta * (safe[o] - dist)  # θ (d − ‖xᵢ − x_o‖), eq. 17
            rel = release if active[i] == o else 0.0
            k = _keep(cons, k, o, dist - safe[o], h0, h1, barrier, radial, radial < barrier + rel)
        if mate_safe > 0.0:
            n_obs = obs.shape[0]
            reach = mate_act * mate_act
            if grid:  # only the teammates in the 3 × 3 cells around robot i can be in reach
                cx = np.floor(x[i, 0] / mate_act)
                cy = np.floor(x[i, 1] / mate_act)
                sorted_ = start[cells]  # every teammate
                for dy in range(-1, 2):  # a row's three cells: buckets h, h + 1, h + 2
                    h = _cell(cx - 1, cy + dy, cells)  # (past the last bucket: the first)
                    end = start[h + 3] if h + 3 <= cells else sorted_ + start[h + 3 - cells]
                    for q in range(start[h], end):
                        k = _mate(
                            i, order[q if q < sorted_ else q - sorted_], x, mates, g0, g1,
                            theta, release, active, n_obs, reach, mate_safe, cons, k,
                        )  # fmt: skip
            else:
                for j in range(mates.shape[0]):
                    k = _mate(
                        i, j, x, mates, g0, g1, theta, release, active, n_obs, reach,
                        mate_safe, cons, k,
                    )  # fmt: skip
        best, du0, du1 = _answer(cons, k, g0, g1, u_g[i, 0], u_g[i, 1], limit, over)
        if active[i] != best:
            changed = True
        active[i] = best
        delta_u[i, 0] = du0
        delta_u[i, 1] = du1
        u[i, 0] = u_g[i, 0] + du0
        u[i, 1] = u_g[i, 1] + du1
    return changed


class Surroundings(NamedTuple):
    """What the robots' sensors report this period (kept by the team, read by the period)."""

    obstacles: np.ndarray  # (O, n) sensed obstacle centres (cylinders, then excluded robots)
    safe: np.ndarray  # (O,) safe distances d
    activation: np.ndarray  # (O,) activation distances
    mates: np.ndarray  # (M, n) where each robot's range sensor sees the members


class SupervisorRecord(NamedTuple):
    """What the compiled period (:mod:`.period`) reads and writes of the supervisor."""

    theta: float
    release: float
    active: np.ndarray  # (M,) the obstacle each robot avoids, or -1
    mate_safe: float  # 0: teammates are not avoided this period
    mate_act: float
    limit: float  # the drive's range per axis (inf: none)


class Supervisor(Block):
    """The paper's local supervisor (eqs. 8, 17-18, 22) on every robot.

    ``active[i]`` is the obstacle robot i is avoiding, or -1 when it follows
    the global mission (α of eq. 8). ``release`` [m/s] only keeps measurement
    noise from toggling the behaviour. Override :meth:`step` to try other
    reactive behaviours; robot i's row may use only its own measured position,
    its own global input and what its own sensors report.
    """

    kind = "supervisor"

    def __init__(self, release: float = 0.01) -> None:
        self.release = float(release)
        self.active = np.zeros(0, dtype=np.intp)
        self.limit = np.inf  # the drive's range per axis, from the team's configuration

    def reset(self, config: TeamConfig, x_m0: np.ndarray, prior: np.ndarray) -> None:
        """Every robot starts on the global mission."""
        self.theta = config.theta
        self.active = np.full(len(x_m0), -1, dtype=np.intp)
        self.mate_safe = float(config.teammate_safe)
        self.mate_act = float(config.teammate_activation)
        self.limit = float(config.input_limit)  # the drive's range, per axis

    def record(self, sensed: bool) -> SupervisorRecord:
        """The state the compiled period updates; teammates are avoided only when the range
        sensors gave a reading (``sensed``)."""
        mate_safe = self.mate_safe if sensed else 0.0
        return SupervisorRecord(
            self.theta, self.release, self.active, mate_safe, self.mate_act, self.limit
        )

    def drop(self, p, graph, t) -> None:
        """Forget the excluded robot's behaviour."""
        self.active = np.delete(self.active, p)

    def step(
        self,
        x: np.ndarray,
        u_g: np.ndarray,
        obstacles: np.ndarray,
        safe: np.ndarray,
        activation: np.ndarray,
        teammates: np.ndarray | None = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Nominal inputs uᵢ (eq. 8) and Δuᵢ (eq. 22), each (M, n).

        ``x`` (M, n) own measured positions, ``u_g`` (M, n) global inputs,
        ``obstacles`` (O, n) sensed centres, ``safe`` d (O,), ``activation`` (O,);
        ``teammates`` (M, n) where each robot's range sensor sees the members (None:
        no sensor reading, no teammate avoided).
        """
        u, du = np.empty(np.shape(u_g)), np.empty(np.shape(u_g))
        mates = np.zeros((0, 2)) if teammates is None else np.ascontiguousarray(teammates, float)
        supervise(
            np.ascontiguousarray(x, float),
            np.ascontiguousarray(u_g, float),
            np.ascontiguousarray(obstacles, float).reshape(-1, 2),
            np.ascontiguousarray(safe, float),
            np.ascontiguousarray(activation, float),
            self.theta,
            self.release,
            self.active,
            u,
            du,
            mates,
            self.mate_safe if teammates is not None else 0.0,
            self.mate_act,
            grid_work(len(mates)),
            self.limit,
        )
        return u, du

    @property
    def reactive(self) -> np.ndarray:
        """Which robots are currently on a reactive behaviour, (M,) bool."""
        return self.active >= 0


def obstacle_label(index: int, n_cylinders: int) -> str:
    """'cylinder k' or 'robot k' (1-based) for what a robot's supervisor avoids."""
    if index < n_cylinders:
        return f"cylinder {index + 1}"
    return f"robot {index - n_cylinders + 1}"
