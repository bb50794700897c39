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

from ..core.graph import Graph
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
def _message(y, links, networked, src, e):  # pragma: no cover - compiled
    """The message ʲŷ that edge e brings (M·n,): the one its link last delivered on a
    network (``networked``), else the sender's current ŷ (row ``src[e]`` of ``y``)."""
    return links[e] if networked else y[src[e]]


@njit(inline="always")
def residual_row(
    y_hat, int_u_own, x_m, src, first_edge, in_degree, links, networked, i, row, scale, half
):  # pragma: no cover - compiled
    """Robot i's ⁱr (eq. 35) into ``row`` (M·n,): Σ_{j∈Nᵢ}(ʲŷ − ⁱŷ) + Πᵢ(y_m,i − ⁱŷᵢ). Robot
    i reads the messages ʲŷ on the edges into it only (``src[first_edge[i]:
    first_edge[i + 1]]``) and its own y_m,i = x_m,i − ∫uᵢ (eq. 21, docs/notes.md, 2). On a
    network (``networked``) the message of edge e is the last one its link delivered,
    ``links[e]`` (M·n,), instead of the sender's current ŷ.

    The sum is taken as −|Nᵢ| ⁱŷ + ʲ¹ŷ + ʲ²ŷ + …, left to right, with up to three messages
    in one loop over the row and any further ones added a loop each: the same floats as a
    loop per message, with the row stored and read back once instead of once a message
    (at N = 1000 and three in-neighbours, the pass's round without the decision took
    2.24-2.35 ms on one core, against 2.42-2.63 ms a loop a message, 2026-11-28).

    Returns how many entries a of the row are *not* below the decision's bound, counted
    in the same loop as the entry is computed: ``not r_a² < half · scale[a]`` (the test
    of a row at rest, :func:`~.decision.quiet_sums`; a NaN anywhere counts). Only the sum
    of up to three messages is tested: with more messages, or the own block's
    measurement term added after the loop, the count says nothing of the final entries
    and the caller tests those itself (the count is then M·n, or the own block is tested
    apart). A ``half`` of NaN tests nothing: every entry counts, whatever ``scale``
    (M·n,) holds."""
    m, _, n = y_hat.shape
    y = y_hat.reshape(m, m * n)  # row i: robot i's message, (k, d) flattened
    own, w = y[i], -in_degree[i]  # one-dimensional views: loops the compiler vectorises
    e, end = first_edge[i], first_edge[i + 1]
    over = 0
    if end - e >= 3:
        m1, m2 = _message(y, links, networked, src, e), _message(y, links, networked, src, e + 1)
        m3 = _message(y, links, networked, src, e + 2)
        for a in range(m * n):
            r = w * own[a] + m1[a] + m2[a] + m3[a]
            row[a] = r
            over += not r * r < half * scale[a]
        e += 3
    elif end - e == 2:
        m1, m2 = _message(y, links, networked, src, e), _message(y, links, networked, src, e + 1)
        for a in range(m * n):
            r = w * own[a] + m1[a] + m2[a]
            row[a] = r
            over += not r * r < half * scale[a]
        e += 2
    elif end - e == 1:
        m1 = _message(y, links, networked, src, e)
        for a in range(m * n):
            r = w * own[a] + m1[a]
            row[a] = r
            over += not r * r < half * scale[a]
        e += 1
    else:
        for a in range(m * n):
            r = w * own[a]
            row[a] = r
            over += not r * r < half * scale[a]
    if e < end:  # a fourth message and beyond: the count was of partial sums
        over = m * n
    for later in range(e, end):
        msg = _message(y, links, networked, src, later)
        for a in range(m * n):
            row[a] += msg[a]
    for d in range(n):
        row[i * n + d] += x_m[i, d] - int_u_own[i, d] - y_hat[i, i, d]
    return over


@njit(inline="always")
def row_norms(row, n, norms):  # pragma: no cover - compiled
    """‖ⁱr_k‖ for every k of robot i's residual ``row`` (M·n,), into ``norms`` (M,): the
    squares first (:func:`~.decision.quiet_row` compares the same floats as it computes
    them), then their square roots in place."""
    if n == 2:  # the plane: the same sums unrolled, which the compiler vectorises
        for k in range(norms.shape[0]):
            norms[k] = row[2 * k] ** 2 + row[2 * k + 1] ** 2
    else:
        for k in range(norms.shape[0]):
            acc = 0.0
            for d in range(n):
                acc += row[k * n + d] ** 2
            norms[k] = acc
    for k in range(norms.shape[0]):
        norms[k] = np.sqrt(norms[k])


@njit(cache=True)
def estimate(y_hat, int_u_hat, out):  # pragma: no cover - compiled
    """ⁱx̂ = ⁱŷ + ∫(ⁱû_g + Γᵢᵀ Δuᵢ) for every robot (eq. 21), into ``out`` (M, M, n)."""
    y, s, o = y_hat.reshape(-1), int_u_hat.reshape(-1), out.reshape(-1)
    for a in range(y.shape[0]):
        o[a] = estimate_one(y[a], s[a])


@njit(cache=True)
def residual(
    y_hat, int_u_own, x_m, src, first_edge, in_degree, links, networked, r, r_norm
):  # pragma: no cover - compiled
    """ⁱr (eq. 35) of every robot into ``r`` (M, M, n), ‖ⁱr_k‖ into ``r_norm`` (M, M)."""
    m, _, n = y_hat.shape
    rr = r.reshape(m, m * n)
    for i in range(m):
        row = rr[i]  # no test of the decision's (a NaN half): the row itself as the scale
        residual_row(
            y_hat, int_u_own, x_m, src, first_edge, in_degree, links, networked, i, row, row,
            np.nan,
        )  # fmt: skip
        row_norms(row, n, r_norm[i])


@njit(inline="always")
def integrate_inputs(int_u_hat, int_u_own, delta_u, u, dt):  # pragma: no cover - compiled
    """∫ Γᵢᵀ Δuᵢ into robot i's own block of ∫ⁱû and ∫uᵢ for y_m (eqs. 20-21)."""
    m, _, n = int_u_hat.shape
    for i in range(m):
        for d in range(n):
            int_u_hat[i, i, d] += dt * delta_u[i, d]  # ∫ Γᵢᵀ Δuᵢ
            int_u_own[i, d] += dt * u[i, d]  # ∫ uᵢ, for y_m (eq. 21)


@njit(cache=True)
def update(y_hat, int_u_hat, int_u_own, r, u_hat_g, delta_u, u, ko, dt, dt_o):  # pragma: no cover
    """Advance every robot's observer by one control period, in place (eqs. 19-21, Euler).

    ``u_hat_g`` (M, M, n) is ⁱû_g, ``delta_u`` (M, n) is Δuᵢ (eq. 22) and ``u``
    (M, n) the nominal input uᵢ of eq. 8 each robot applied; the integrals advance by the
    control period ``dt``, ŷ by the observer's step ``dt_o`` (a round, docs/thresholds.md).
    """
    s, g = int_u_hat.reshape(-1), u_hat_g.reshape(-1)
    for a in range(s.shape[0]):
        s[a] += dt * g[a]  # ∫ ⁱû_g
    integrate_inputs(int_u_hat, int_u_own, delta_u, u, dt)
    y, rr = y_hat.reshape(-1), r.reshape(-1)
    for a in range(y.shape[0]):
        y[a] = advance_one(y[a], rr[a], ko, dt_o)


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
        none = np.zeros((0, m * y_hat.shape[2]))
        residual(
            y_hat,
            own,
            diag,
            self.src,
            self.first_edge,
            self.in_degree,
            none,
            False,
            r,
            r_norm,
        )
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
    links: np.ndarray  # (E, M·n) the last message each link delivered (a network)
    networked: bool  # read ``links`` instead of the senders' current ŷ
    ko: float
    dt: float  # the control period: the integrals
    dt_o: float  # the observer's step, a round of the network (eq. 19)


#: rounds of broadcasts a robot keeps for its radio (a message in flight carries a round at
#: most one older than the newest: a delay is shorter than a round)
SENT_ROUNDS = 3


class Observer(Block):
    """The paper's consensus observer (eqs. 19-21) and residual (eq. 35) on every robot.

    State, updated in place: ``y_hat`` (M, M, n) ⁱŷ, the messages each robot
    broadcasts; ``int_u_hat`` (M, M, n) ∫(ⁱû_g + Γᵢᵀ Δuᵢ); ``int_u_own``
    (M, n) ∫uᵢ. Every robot starts believing its teammates are at their planned
    slots (``prior``) and itself where it measures itself.

    On a network (``config.networked``) a robot reads, for each in-neighbour, the last
    message its link delivered (``links``, filled by :meth:`receive`) and knows which
    round it carries (``link_round``); ŷ steps once per round of the network (β = k_o h_o,
    h_o = ``config.observer_period``), the integrals every control period.

    Override :meth:`estimate`, :meth:`residual` and :meth:`update` to try
    another observer; row i of what they return may use only robot i's own
    row of the state, its own measurement and inputs, and the rows of
    ``y_hat`` of its in-neighbours (``self.messages``).
    """

    kind = "observer"

    def reset(self, config: TeamConfig, x_m0: np.ndarray, prior: np.ndarray) -> None:
        """Start every robot's estimate: ⁱx̂(0) = ``prior`` except ⁱx̂ᵢ(0) = x_m,i(0)."""
        n = len(x_m0)
        self.ko, self.dt, self.dt_o = config.ko, config.dt, config.observer_period
        self.networked = bool(config.networked)
        self.y_hat = np.repeat(np.asarray(prior, float)[None], n, axis=0)
        self.y_hat[np.arange(n), np.arange(n)] = x_m0
        self.int_u_hat = np.zeros_like(self.y_hat)
        self.int_u_own = np.zeros((n, self.y_hat.shape[2]))
        self.allowed = Messages(config.graph.edges, n)  # the links a message may take
        width = n * self.y_hat.shape[2]
        if self.networked:
            # the start: the robots exchange ŷ(0) before the mission (round 0 at period 0)
            self.links = np.ascontiguousarray(self.y_hat[self.allowed.src].reshape(-1, width))
            self.sent = np.repeat(self.y_hat.reshape(1, n, width), SENT_ROUNDS, axis=0)
        else:
            self.links = np.zeros((0, width))
            self.sent = np.zeros((0, n, width))
        self.link_round = np.zeros(len(self.allowed.src), dtype=np.int64)  # ŷ(0) is in
        self._connect(config.graph)

    def link_dst(self) -> np.ndarray:
        """The receiving robot of each of :attr:`allowed`'s links."""
        fe = self.allowed.first_edge
        return np.repeat(np.arange(len(fe) - 1), np.diff(fe))

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
            self.links,
            self.networked,
            self.ko,
            self.dt,
            self.dt_o,
        )

    def advance(self) -> None:
        """ŷ of the next period (eq. 19), which the compiled period wrote into ``y_next``,
        becomes the current one."""
        self.y_hat, self.y_next = self.y_next, self.y_hat

    # ------------------------------------------------------------------ the radio

    def broadcast(self, content_round: int) -> None:
        """Keep ŷ as the message of ``content_round`` (what the radio sends from now on)."""
        if self.networked:
            self.sent[content_round % SENT_ROUNDS] = self.y_hat.reshape(len(self.y_hat), -1)

    def receive(self, links: np.ndarray, rounds: np.ndarray, offset: np.ndarray) -> None:
        """Links ``links`` (indices into :attr:`allowed`) delivered the messages of
        ``rounds``, each with ``offset`` [m] added by a corrupting sender."""
        if not len(links):
            return
        src = self.allowed.src[links]
        self.links[links] = self.sent[rounds % SENT_ROUNDS, src]
        if offset.any():
            self.links[links] += offset[:, None]
        self.link_round[links] = rounds

    # ------------------------------------------------------------------ exclusions

    def drop(self, p: int, graph: Graph, t: float) -> None:
        """Robot at team position ``p`` leaves: every collective vector shrinks (§5.2.2)."""
        m, _, n = self.y_hat.shape
        keep = np.delete(np.arange(m), p)
        self.y_hat = self.y_hat[np.ix_(keep, keep)]
        self.int_u_hat = self.int_u_hat[np.ix_(keep, keep)]
        self.int_u_own = self.int_u_own[keep]
        if self.networked:
            al, dst = self.allowed, self.link_dst()
            stay = (al.src != p) & (dst != p)
            cols = np.delete(np.arange(m * n).reshape(m, n), p, axis=0).ravel()
            self.links = np.ascontiguousarray(self.links[np.ix_(stay, cols)])
            self.sent = np.ascontiguousarray(self.sent[:, keep][:, :, cols])
            self.link_round = self.link_round[stay]
            j_new = al.src[stay] - (al.src[stay] > p)
            i_new = dst[stay] - (dst[stay] > p)
            edges = tuple(zip(j_new.tolist(), i_new.tolist(), strict=True))
            self.allowed = Messages(edges, m - 1)
        self._connect(graph)

    # ------------------------------------------------------------------ the equations

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
            self.links,
            self.networked,
            self._r,
            self._r_norm,
        )
        return self._r

    def update(
        self, r: np.ndarray, u_hat_g: np.ndarray, delta_u: np.ndarray, u: np.ndarray
    ) -> None:
        """Advance by one control period (eqs. 19-21) with the period's residual and inputs
        (between two rounds of a network the team passes r = 0: only the integrals move)."""
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
            self.dt_o,
        )
