"""The paper's adaptive thresholds ⁱμ_k(t) (eqs. 40-41), the default rule ``"paper"``.

:class:`Thresholds` is the thresholds block (the plug-in point of every rule: the other
rules subclass it) and :func:`eq40` its compiled evaluation, with κ, λ from
:mod:`.decay`. It restarts at each exclusion from a bound valid at that instant
(docs/notes.md, 7)."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from ...core.graph import Graph
from ..block import Block, TeamConfig
from .decay import decay_bounds


class ThresholdRecord(NamedTuple):
    """This round's ⁱμ_k as the compiled period reads them (:func:`threshold_at`): a dense
    (M, M) array, or, for eq. 40 (``dense`` of shape (0, 0)), its factors: ⁱμ_k =
    (cᵢ + δᵢₖ) b_k + δᵢₖ η̄ with cᵢ = √n dᵢ, b_k the bound of ‖ỹ*_k‖, +inf where λ_k = 0
    (not ``finite[k]``), so no N × N array is written or read per period. Until the bound
    settles the compiled period writes it itself at its start (:func:`refresh_bound`, from
    ``start``, ``steady``, ``lam`` and the elapsed time in ``clock``): one compiled call a
    period less (0.6 µs at N = 4)."""

    dense: np.ndarray  # (M, M), or (0, 0): the factors below
    coef: np.ndarray  # (M,) √n dᵢ
    bound: np.ndarray  # (M,) the bound of ‖ỹ*_k(t)‖
    finite: np.ndarray  # (M,) bool: λ_k > 0
    start: np.ndarray  # (M,) κ‖ỹ*_k(0)‖ (bound_of's ``start``)
    steady: np.ndarray  # (M,) κ(k_o η̄ + √N ξ̄)/λ_k (bound_of's ``steady``)
    lam: np.ndarray  # (M,) λ_k
    clock: np.ndarray  # (1,) t − t0 of ``bound`` to write, or < 0: ``bound`` is written
    eta: float  # η̄


_NONE = np.zeros(0)
_WRITTEN = np.full(1, -1.0)  # the clock of a record whose bound needs no writing (never set)


def dense_thresholds(mu: np.ndarray) -> ThresholdRecord:
    """The record of thresholds given as an (M, M) array."""
    return ThresholdRecord(mu, _NONE, _NONE, np.zeros(0, bool), _NONE, _NONE, _NONE, _WRITTEN, 0.0)


@njit(inline="always")
def factored_at(coef, bound, finite, eta, i, k):  # pragma: no cover - compiled
    """ⁱμ_k = (cᵢ + δᵢₖ) b_k + δᵢₖ η̄ of eq. 40 from its factors, +inf where λ_k = 0 (the
    numbers of the (M, M) form (√n dᵢ + δᵢₖ) b_k + δᵢₖ η̄: its off-diagonal δᵢₖ η̄ adds +0.0)."""
    if not finite[k]:
        return np.inf
    if i == k:
        return (coef[i] + 1.0) * bound[k] + eta
    return coef[i] * bound[k]


@njit(inline="always")
def threshold_at(th, i, k):  # pragma: no cover - compiled
    """ⁱμ_k of the record ``th`` (:class:`ThresholdRecord`)."""
    if th.dense.shape[0]:
        return th.dense[i, k]
    return factored_at(th.coef, th.bound, th.finite, th.eta, i, k)


@njit(cache=True)
def bound_of(start, steady, lam, elapsed, bound):  # pragma: no cover - compiled
    """The bound of ‖ỹ*_k(t)‖ in eq. 40 for every k, into ``bound`` (M,):
    ‖ỹ*_k(0)‖ κ e^{−λt} + κ(k_o η̄ + √N ξ̄)/λ (1 − e^{−λt}) with ``start`` = κ‖ỹ*_k(0)‖
    and ``steady`` = κ(k_o η̄ + √N ξ̄)/λ; +inf where λ_k = 0 (no bound: the graph is not
    strongly connected)."""
    for k in range(bound.shape[0]):
        if lam[k] > 0:
            decay = np.exp(-lam[k] * elapsed)
            bound[k] = start[k] * decay + steady[k] * (1.0 - decay)
        else:
            bound[k] = np.inf


@njit(cache=True, inline="always")
def refresh_bound(th):  # pragma: no cover - compiled
    """The record ``th``'s bound of ‖ỹ*_k(t)‖ written for the elapsed time in its clock
    (:func:`bound_of`), once: the clock is then set below zero."""
    if th.clock[0] >= 0:
        bound_of(th.start, th.steady, th.lam, th.clock[0], th.bound)
        th.clock[0] = -1.0


@njit(cache=True)
def eq40(coef, bound, finite, eta, out):  # pragma: no cover - compiled
    """ⁱμ_k(t) of eq. 40 (:func:`factored_at`) into ``out`` (M, M), row by row, in memory
    order (column by column was 4.4× slower). The compiled period does not call it: it reads
    the factors (:func:`threshold_at`). Arrays, not the record: from Python numba types a
    tuple argument element by element on every call (µs at N = 4)."""
    for i in range(out.shape[0]):
        for k in range(out.shape[1]):
            out[i, k] = factored_at(coef, bound, finite, eta, i, k)


class Thresholds(Block):
    """The paper's adaptive thresholds ⁱμ_k(t) (eqs. 40-41) for every robot i and robot k.

    Restarted at each exclusion from a bound valid at that instant, with κ, λ
    of the new graph (docs/notes.md, 7). Override :meth:`mu` (and :meth:`restart`) to try
    another rule; row i may use only what robot i knows: the graph, the gains,
    the noise bounds and the time.
    """

    kind = "thresholds"
    #: what ``initial_error_bound`` bounds for this rule: "stacked", ‖ỹ*_k(0)‖ over every
    #: observer (eq. 40), or "robot", each robot's start distance from its planned slot
    initial_error: str = "stacked"

    def reset(self, config: TeamConfig, x_m0: np.ndarray, prior: np.ndarray) -> None:
        """Start from ‖ỹ*_k(0)‖ ≤ ``initial_error_bound`` for every k."""
        self.ko, self.eta_bar, self.xi_bar = config.ko, config.eta_bar, config.xi_bar
        self.n_dim = np.shape(x_m0)[1]
        self.restart(config.graph, np.full(config.graph.n, config.initial_error_bound), 0.0)

    @classmethod
    def for_graph(
        cls,
        graph: Graph,
        ko: float,
        eta_bar: float,
        xi_bar: float,
        y0: np.ndarray,
        t0: float = 0.0,
        n_dim: int = 2,
        dt: float = 0.01,
        K: float = 3.0,
        G: float = 0.01,
    ) -> Thresholds:
        """The rule on ``graph`` with ‖ỹ*_k(t0)‖ ≤ ``y0[k]``, outside any team (control
        period ``dt``, fault-estimator gains K, G as scalars times I; no compensation, so
        ē is the rule's own ``drift_bound``)."""
        from ...core.mission import Formation, polygon_offsets

        config = TeamConfig(
            graph=graph,
            kc=1.0,
            ko=ko,
            K=K * np.eye(n_dim),
            G=G * np.eye(n_dim),
            theta=1.0,
            dt=dt,
            eta_bar=eta_bar,
            xi_bar=xi_bar,
            formation=Formation(),
            obstacle_position=np.zeros((0, 2)),
            obstacle_safe=np.zeros(0),
            obstacle_activation=np.zeros(0),
            compensate=False,
        )
        th = cls()
        slots = polygon_offsets(graph.n, 0.5)
        th.reset(config, slots, slots)
        if t0 or not np.allclose(y0, config.initial_error_bound):
            th.restart(graph, np.asarray(y0, float), t0)
        return th

    def restart(self, graph: Graph, y0: np.ndarray, t0: float) -> None:
        """Start anew at ``t0`` on ``graph`` with ‖ỹ*_k(t0)‖ ≤ ``y0[k]`` (docs/notes.md, 7)."""
        self.graph, self.y0, self.t0 = graph, y0, t0
        self.kappa, self.lam = decay_bounds(graph, self.ko)
        n = graph.n
        with np.errstate(divide="ignore", invalid="ignore"):
            self._steady = np.where(
                self.lam > 0,
                self.kappa * (self.ko * self.eta_bar + np.sqrt(n) * self.xi_bar) / self.lam,
                np.inf,
            )
        self._finite = self.lam > 0
        self._start = np.where(self._finite, y0 * self.kappa, 0.0)  # finite parts only
        self._steady_f = np.where(self._finite, self._steady, 0.0)
        # after this long every transient term of eq. 40 is below 1e-12 of its start
        finite = self.lam[self.lam > 0]
        self._settled = t0 + (28.0 / finite.min() if len(finite) else np.inf)
        self._steady_bound: np.ndarray | None = None
        self._mu_buf = np.empty((0, 0))  # eq. 40 as an array, written when asked for
        self._mu_at = np.nan  # the time _mu_buf holds
        self._mu_steady: np.ndarray | None = None  # eq. 40 once settled, an array of its own
        self._bound = np.empty(n)
        self._clock = np.full(1, -1.0)  # the record's clock (refresh_bound)
        self._record_settled = False  # the record holds the settled bound
        self._record_t = np.nan  # the time of the record's transient bound
        # eq. 40's factors (ThresholdRecord): √n dᵢ, the bound, λ_k > 0, η̄
        coef = np.sqrt(self.n_dim) * graph.in_degree()
        self._record = ThresholdRecord(
            np.zeros((0, 0)), coef, self._bound, self._finite, self._start, self._steady_f,
            self.lam, self._clock, float(self.eta_bar),
        )  # fmt: skip

    def drop(self, p: int, graph: Graph, t: float) -> None:
        """Restart on the reduced graph from the bound ‖ỹ*_k(t)‖ of the robots left."""
        keep = np.delete(np.arange(self.graph.n), p)
        self.restart(graph, self.bracket(t)[keep], t)

    def bracket(self, t: float) -> np.ndarray:
        """‖ỹ*_k(0)‖ κ e^{−λt} + κ(k_o η̄ + √N ξ̄)/λ (1 − e^{−λt}), per k: bounds ‖ỹ*_k(t)‖."""
        b = np.empty(len(self.lam))
        bound_of(self._start, self._steady_f, self.lam, max(t - self.t0, 0.0), b)
        return b

    def mu(self, t: float) -> np.ndarray:
        """ⁱμ_k(t) (M, M) for every observer i (rows) and monitored robot k (columns) (eq. 40).

        Where no bound exists (λ_k = 0: the graph is not strongly connected) the
        threshold is +inf: robot k cannot be judged. The array returned is
        valid until the next call.
        """
        rec, n = self._record, len(self.lam)
        if t >= self._settled:  # one array from the settling time on, kept apart
            if self._mu_steady is None:
                self._mu_steady = np.empty((n, n))
                eq40(rec.coef, self._bound_at(t), rec.finite, rec.eta, self._mu_steady)
            return self._mu_steady
        if self._mu_at != t:
            if self._mu_buf.shape != (n, n):
                self._mu_buf = np.empty((n, n))
            # the record's bound is this t's when the period has just written it (its clock)
            written = t == self._record_t and self._clock[0] < 0
            bound = rec.bound if written else self._bound_at(t)
            eq40(rec.coef, bound, rec.finite, rec.eta, self._mu_buf)
            self._mu_at = t
        return self._mu_buf

    def record(self, t: float) -> ThresholdRecord:
        """ⁱμ_k(t) as the compiled period reads them: eq. 40's factors (O(M) per period,
        nothing once settled), or, for a rule that overrides :meth:`mu`, its array."""
        if type(self).mu is not Thresholds.mu:
            return dense_thresholds(np.ascontiguousarray(self.mu(t), dtype=float))
        if t < self._settled:  # the compiled period writes the bound (refresh_bound)
            self._clock[0] = max(t - self.t0, 0.0)
            self._record_settled, self._record_t = False, t
        elif not self._record_settled:
            self._bound[:] = self._bound_at(t)
            self._clock[0] = -1.0
            self._record_settled, self._record_t = True, np.nan
        return self._record

    def factors_at(self, t: float) -> ThresholdRecord | None:
        """ⁱμ_k(t) as eq. 40's factors, the numbers :meth:`mu` writes out (the same bound of
        ‖ỹ*_k(t)‖), for a reader that need not write the (M, M) array; None for a rule that
        overrides :meth:`mu`."""
        if type(self).mu is not Thresholds.mu:
            return None
        rec = self._record
        bound = self._bound_at(t)
        return rec._replace(bound=bound, clock=_WRITTEN)

    def _bound_at(self, t: float) -> np.ndarray:
        """The bound of ‖ỹ*_k(t)‖ (:func:`bound_of`; not the record's array); kept from the
        first call at or past the settling time on (every transient term is then below
        1e-12 of its start)."""
        if t >= self._settled and self._steady_bound is not None:
            return self._steady_bound
        bound = np.empty(len(self.lam))
        bound_of(self._start, self._steady_f, self.lam, max(t - self.t0, 0.0), bound)
        if t >= self._settled:
            self._steady_bound = bound
        return bound
