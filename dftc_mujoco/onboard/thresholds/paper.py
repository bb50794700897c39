"""The paper's adaptive thresholds ⁱμ_k(t) (eqs. 40-41), the default rule ``"paper"``.

:class:`Thresholds` is the thresholds block (the plug-in point of every rule: the other
rules subclass it) and :func:`eq40` its compiled evaluation, with κ, λ from
:mod:`.decay`. It restarts at each exclusion from a bound valid at that instant
(docs/notes.md, 7)."""

from __future__ import annotations

import numpy as np
from numba import njit

from ...graph import Graph
from ..block import Block, TeamConfig
from .decay import decay_bounds


@njit(cache=True)
def eq40(start, steady, lam, elapsed, coef, eta, out, bound):  # pragma: no cover - compiled
    """ⁱμ_k(t) = (√n dᵢ + δᵢₖ)·‖ỹ*_k‖-bound + δᵢₖ η̄ into ``out`` (M, M) (eq. 40).

    The bound of ‖ỹ*_k(t)‖ is ‖ỹ*_k(0)‖ κ e^{−λt} + κ(k_o η̄ + √N ξ̄)/λ (1 − e^{−λt})
    with ``start`` = κ‖ỹ*_k(0)‖ and ``steady`` = κ(k_o η̄ + √N ξ̄)/λ, into ``bound`` (M,);
    where λ_k = 0 (no bound: the graph is not strongly connected) the threshold is +inf.
    ``out`` is written row by row, in memory order (column by column was 4.4× slower).
    """
    for k in range(out.shape[1]):
        if lam[k] > 0:
            decay = np.exp(-lam[k] * elapsed)
            bound[k] = start[k] * decay + steady[k] * (1.0 - decay)
        else:
            bound[k] = np.inf
    for i in range(out.shape[0]):
        for k in range(out.shape[1]):
            if lam[k] > 0:
                out[i, k] = coef[i, k] * bound[k] + eta[i, k]
            else:
                out[i, k] = np.inf


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
        from ...mission import Formation, polygon_offsets

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
        eye = np.eye(n)
        self._coef = np.sqrt(self.n_dim) * graph.in_degree()[:, None] + eye  # √n dᵢ + δᵢₖ
        self._eta = self.eta_bar * eye  # δᵢₖ η̄
        with np.errstate(divide="ignore", invalid="ignore"):
            self._steady = np.where(
                self.lam > 0,
                self.kappa * (self.ko * self.eta_bar + np.sqrt(n) * self.xi_bar) / self.lam,
                np.inf,
            )
        self._finite = self.lam > 0
        self._all_finite = bool(self._finite.all())
        self._start = np.where(self._finite, y0 * self.kappa, 0.0)  # finite parts only
        self._steady_f = np.where(self._finite, self._steady, 0.0)
        # after this long every transient term of eq. 40 is below 1e-12 of its start
        finite = self.lam[self.lam > 0]
        self._settled = t0 + (28.0 / finite.min() if len(finite) else np.inf)
        self._mu_steady: np.ndarray | None = None
        self._mu_buf = np.empty((n, n))
        self._bound = np.empty(n)

    def drop(self, p: int, graph: Graph, t: float) -> None:
        """Restart on the reduced graph from the bound ‖ỹ*_k(t)‖ of the robots left."""
        keep = np.delete(np.arange(self.graph.n), p)
        self.restart(graph, self.bracket(t)[keep], t)

    def bracket(self, t: float) -> np.ndarray:
        """‖ỹ*_k(0)‖ κ e^{−λt} + κ(k_o η̄ + √N ξ̄)/λ (1 − e^{−λt}), per k: bounds ‖ỹ*_k(t)‖."""
        decay = np.exp(-self.lam * max(t - self.t0, 0.0))
        b = self._start * decay + self._steady_f * (1.0 - decay)
        if not self._all_finite:
            b[~self._finite] = np.inf
        return b

    def mu(self, t: float) -> np.ndarray:
        """ⁱμ_k(t) (M, M) for every observer i (rows) and monitored robot k (columns) (eq. 40).

        Where no bound exists (λ_k = 0: the graph is not strongly connected) the
        threshold is +inf: robot k cannot be judged. The array returned is
        valid until the next call.
        """
        if t >= self._settled:
            if self._mu_steady is None:
                self._mu_steady = self._mu(t).copy()
            return self._mu_steady
        return self._mu(t)

    def _mu(self, t: float) -> np.ndarray:
        elapsed = max(t - self.t0, 0.0)
        eq40(
            self._start,
            self._steady_f,
            self.lam,
            elapsed,
            self._coef,
            self._eta,
            self._mu_buf,
            self._bound,
        )
        return self._mu_buf
