"""Distributed consensus observer in y-form (eqs. 19-21) and its residual (eq. 35).

Every robot i keeps ⁱŷ (its estimate of the auxiliary collective variable
y = x − ∫u, eq. 20) and ∫(ⁱû_g + Γᵢᵀ Δuᵢ); its estimate of the whole team is
ⁱx̂ = ⁱŷ + ∫(ⁱû_g + Γᵢᵀ Δuᵢ) (eq. 21). Eq. 19 is then d/dt ⁱŷ = k_o ⁱr with
ⁱr the residual of eq. 35 (docs/notes.md, 1). Arrays carry a leading robot axis (the
members of the team): ``y_hat[i]`` is robot i's ⁱŷ, of shape (M, n), and is
the message it broadcasts.

The equations are the compiled functions :func:`estimate`, :func:`residual`
and :func:`update`; :class:`Observer` is the block that holds the state and
calls them, and the compiled team period (:mod:`.period`) calls the same
functions.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from ..graph import Graph
from .block import Block, TeamConfig


@njit(inline="always")
def estimate_one(y, s):  # pragma: no cover - compiled
    """One entry of ⁱx̂ = ⁱŷ + ∫(ⁱû_g + Γᵢᵀ Δuᵢ) (eq. 21)."""
    return y + s


@njit(inline="always")
def advance_one(y, r, ko, dt):  # pragma: no cover - compiled
    """One entry of ⁱŷ after a period: d/dt ⁱŷ = k_o ⁱr (eq. 19, y-form, forward Euler)."""
    return y + ko * dt * r


@njit(inline="always")
def residual_row(y_hat, int_u_own, x_m, src, first_edge, in_degree, i, row):  # pragma: no cover
    """Robot i's ⁱr (eq. 35) into ``row`` (M·n,): Σ_{j∈Nᵢ}(ʲŷ − ⁱŷ) + Πᵢ(y_m,i − ⁱŷᵢ); returns
    nothing. Robot i reads the messages ʲŷ on the edges into it only (``src[first_edge[i]:
    first_edge[i + 1]]``) and its own y_m,i = x_m,i − ∫uᵢ (eq. 21, docs/notes.md, 2)."""
    m, _, n = y_hat.shape
    y = y_hat.reshape(m, m * n)  # row i: robot i's message, (k, d) flattened
    for a in range(m * n):
        row[a] = -in_degree[i] * y[i, a]
    for e in range(first_edge[i], first_edge[i + 1]):
        j = src[e]
        for a in range(m * n):
            row[a] += y[j, a]
    for d in range(n):
        row[i * n + d] += x_m[i, d] - int_u_own[i, d] - y_hat[i, i, d]


@njit(inline="always")
def row_norms(row, i, n, r_norm):  # pragma: no cover - compiled
    """‖ⁱr_k‖ for every k of robot i's residual ``row`` (M·n,), into ``r_norm[i]``."""
    for k in range(r_norm.shape[1]):
        acc = 0.0
        for d in range(n):
            acc += row[k * n + d] ** 2
        r_norm[i, k] = np.sqrt(acc)


@njit(cache=True)
def estimate(y_hat, int_u_hat, out):  # pragma: no cover - compiled
    """ⁱx̂ = ⁱŷ + ∫(ⁱû_g + Γᵢᵀ Δuᵢ) for every robot (eq. 21), into ``out`` (M, M, n)."""
    y, s, o = y_hat.reshape(-1), int_u_hat.reshape(-1), out.reshape(-1)
    for a in range(y.shape[0]):
        o[a] = estimate_one(y[a], s[a])


@njit(cache=True)
def residual(y_hat, int_u_own, x_m, src, first_edge, in_degree, r, r_norm):  # pragma: no cover
    """ⁱr (eq. 35) of every robot into ``r`` (M, M, n), ‖ⁱr_k‖ into ``r_norm`` (M, M)."""
    m, _, n = y_hat.shape
    rr = r.reshape(m, m * n)
    for i in range(m):
        residual_row(y_hat, int_u_own, x_m, src, first_edge, in_degree, i, rr[i])
        row_norms(rr[i], i, n, r_norm)


@njit(inline="always")
def integrate_inputs(int_u_hat, int_u_own, delta_u, u, dt):  # pragma: no cover - compiled
    """∫ Γᵢᵀ Δuᵢ into robot i's own block of ∫ⁱû and ∫uᵢ for y_m (eqs. 20-21)."""
    m, _, n = int_u_hat.shape
    for i in range(m):
        for d in range(n):
            int_u_hat[i, i, d] += dt * delta_u[i, d]  # ∫ Γᵢᵀ Δuᵢ
            int_u_own[i, d] += dt * u[i, d]  # ∫ uᵢ, for y_m (eq. 21)


@njit(cache=True)
def update(y_hat, int_u_hat, int_u_own, r, u_hat_g, delta_u, u, ko, dt):  # pragma: no cover
    """Advance every robot's observer by one control period, in place (eqs. 19-21, Euler).

    ``u_hat_g`` (M, M, n) is ⁱû_g, ``delta_u`` (M, n) is Δuᵢ (eq. 22) and ``u``
    (M, n) the nominal input uᵢ of eq. 8 each robot applied.
    """
    s, g = int_u_hat.reshape(-1), u_hat_g.reshape(-1)
    for a in range(s.shape[0]):
        s[a] += dt * g[a]  # ∫ ⁱû_g
    integrate_inputs(int_u_hat, int_u_own, delta_u, u, dt)
    y, rr = y_hat.reshape(-1), r.reshape(-1)
    for a in range(y.shape[0]):
        y[a] = advance_one(y[a], rr[a], ko, dt)


class Messages:
    """Who hears whom: the broadcast ŷ travels along the graph's edges only.

    The edges into robot i are ``src[first_edge[i]:first_edge[i + 1]]``, so a
    function that sums over them cannot read a robot that is not i's
    in-neighbour.
    """

    def __init__(self, edges: tuple[tuple[int, int], ...], n: int):
        order = sorted(edges, key=lambda e: (e[1], e[0]))
        self.src = np.array([j for j, _ in order], dtype=np.intp)
        dst = np.array([i for _, i in order], dtype=np.intp)
        self.in_degree = np.bincount(dst, minlength=n).astype(float)
        self.first_edge = np.searchsorted(dst, np.arange(n + 1)).astype(np.intp)

    def neighbour_sum(self, y_hat: np.ndarray) -> np.ndarray:
        """Σ_{j∈Nᵢ} (ʲŷ − ⁱŷ) for every robot i, shape (M, M, n) (the consensus part of eq. 35)."""
        m = len(y_hat)
        r, r_norm = np.empty_like(y_hat), np.empty((m, m))
        own = np.zeros((m, y_hat.shape[2]))
        diag = y_hat[np.arange(m), np.arange(m)]
        residual(y_hat, own, diag, self.src, self.first_edge, self.in_degree, r, r_norm)
        return r


class ObserverRecord(NamedTuple):
    """What the compiled period (:mod:`.period`) reads and writes of the observer."""

    y_hat: np.ndarray  # (M, M, n) ⁱŷ, the messages
    y_next: np.ndarray  # (M, M, n) ⁱŷ of the next period, written by the period
    int_u_hat: np.ndarray  # (M, M, n) ∫(ⁱû_g + Γᵢᵀ Δuᵢ)
    int_u_own: np.ndarray  # (M, n) ∫uᵢ
    src: np.ndarray  # the edges into each robot (:class:`Messages`)
    first_edge: np.ndarray
    in_degree: np.ndarray
    ko: float
    dt: float


class Observer(Block):
    """The paper's consensus observer (eqs. 19-21) and residual (eq. 35) on every robot.

    State, updated in place: ``y_hat`` (M, M, n) ⁱŷ, the messages each robot
    broadcasts; ``int_u_hat`` (M, M, n) ∫(ⁱû_g + Γᵢᵀ Δuᵢ); ``int_u_own``
    (M, n) ∫uᵢ. Every robot starts believing its teammates are at their planned
    slots (``prior``) and itself where it measures itself.

    Override :meth:`estimate`, :meth:`residual` and :meth:`update` to try
    another observer; row i of what they return may use only robot i's own
    row of the state, its own measurement and inputs, and the rows of
    ``y_hat`` of its in-neighbours (``self.messages``).
    """

    kind = "observer"

    def reset(self, config: TeamConfig, x_m0: np.ndarray, prior: np.ndarray) -> None:
        """Start every robot's estimate: ⁱx̂(0) = ``prior`` except ⁱx̂ᵢ(0) = x_m,i(0)."""
        n = len(x_m0)
        self.ko, self.dt = config.ko, config.dt
        self.y_hat = np.repeat(np.asarray(prior, float)[None], n, axis=0)
        self.y_hat[np.arange(n), np.arange(n)] = x_m0
        self.int_u_hat = np.zeros_like(self.y_hat)
        self.int_u_own = np.zeros((n, self.y_hat.shape[2]))
        self._connect(config.graph)

    def _connect(self, graph: Graph) -> None:
        self.messages = Messages(graph.edges, graph.n)
        m = self.y_hat.shape[0]
        self.y_next = np.empty_like(self.y_hat)  # the compiled period writes ŷ⁺ here, then swaps
        self._x_hat = np.empty_like(self.y_hat)
        self._r = np.empty_like(self.y_hat)
        self._r_norm = np.empty((m, m))

    def record(self) -> ObserverRecord:
        """The state the compiled period advances; :meth:`advance` after it."""
        msg = self.messages
        return ObserverRecord(
            self.y_hat,
            self.y_next,
            self.int_u_hat,
            self.int_u_own,
            msg.src,
            msg.first_edge,
            msg.in_degree,
            self.ko,
            self.dt,
        )

    def advance(self) -> None:
        """ŷ of the next period (eq. 19), which the compiled period wrote into ``y_next``,
        becomes the current one."""
        self.y_hat, self.y_next = self.y_next, self.y_hat

    def drop(self, p: int, graph: Graph, t: float) -> None:
        """Robot at team position ``p`` leaves: every collective vector shrinks (§5.2.2)."""
        keep = np.delete(np.arange(len(self.y_hat)), p)
        self.y_hat = self.y_hat[np.ix_(keep, keep)]
        self.int_u_hat = self.int_u_hat[np.ix_(keep, keep)]
        self.int_u_own = self.int_u_own[keep]
        self._connect(graph)

    def estimate(self) -> np.ndarray:
        """ⁱx̂ of every robot (eq. 21), shape (M, M, n); valid until the next call."""
        estimate(self.y_hat, self.int_u_hat, self._x_hat)
        return self._x_hat

    def residual(self, x_m: np.ndarray) -> np.ndarray:
        """ⁱr of every robot (eq. 35), shape (M, M, n), from the members' own ``x_m`` (M, n)."""
        msg = self.messages
        residual(
            self.y_hat,
            self.int_u_own,
            np.ascontiguousarray(x_m, dtype=float),
            msg.src,
            msg.first_edge,
            msg.in_degree,
            self._r,
            self._r_norm,
        )
        return self._r

    def update(
        self, r: np.ndarray, u_hat_g: np.ndarray, delta_u: np.ndarray, u: np.ndarray
    ) -> None:
        """Advance by one control period (eqs. 19-21) with the period's residual and inputs."""
        update(
            self.y_hat,
            self.int_u_hat,
            self.int_u_own,
            np.ascontiguousarray(r, dtype=float),
            np.ascontiguousarray(u_hat_g, dtype=float),
            np.ascontiguousarray(delta_u, dtype=float),
            np.ascontiguousarray(u, dtype=float),
            self.ko,
            self.dt,
        )
