"""Threshold rules beside the paper's eq. 40, derived for the discrete-time observer.

``docs/thresholds.md`` has the derivations. The observer runs by forward Euler
at the control period h; with M_k = k_o(L + e_k e_kᵀ) and A_k = I − h M_k:

* ``block_row``: with ‖η_k‖ ≤ η̄ and a drift of y_k = x_k − ∫u_k within h ξ̄ per
  period, ⁱμ_k(t) = ‖e_iᵀ(M_k/k_o)A_k^t‖ y0_k + h(k_o η̄ + √N ξ̄) Σ_{j<t} ‖e_iᵀ(M_k/k_o)A_k^j‖
  + δ_ik η̄ (the discrete form of the bound proposed in issue 10).
* ``drive``: robot k's own measured y_m,k = x_m,k − ∫u_k equals y_m,k(0) + G φ̂_k(t)
  exactly (the fault estimator's algebra, any plant), so
  ⁱr_k(t) = −[(M_k/k_o)A_k^t]_{i,:} ε_k(0) + Σ_{m<t} c_m G φ̂_k(t − m) with
  c_0 = δ_ik, c_m = [A_k^m − A_k^{m−1}]_{ik}, and
  ⁱμ_k(t) = ‖e_iᵀ(M_k/k_o)A_k^t‖ ε̄0 + TV_ik(t) ‖G‖ Φ̄, TV_ik(t) = Σ_{m<t} |c_m|,
  where Φ̄ bounds a healthy robot's ‖φ̂‖ (from the fault estimator's closed loop
  on an ideal plant with η̄ and ξ̄, unless given).

Both are tabulated once per graph (batched over the monitored robots k) until
A_k^t has decayed below 1e-6, with a rigorous bound for later times.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import ScenarioError
from ..graph import Graph
from .block import TeamConfig
from .fdir import Thresholds


def _two_norm_bound(q: np.ndarray) -> np.ndarray:
    """‖Q‖₂ ≤ √(‖Q‖₁ ‖Q‖_∞) for each matrix of the stack ``q`` (K, N, N)."""
    a = np.abs(q)
    return np.sqrt(a.sum(axis=1).max(axis=1) * a.sum(axis=2).max(axis=1))


@dataclass(frozen=True)
class ObserverTables:
    """Powers of every A_k = I − h k_o(L + e_k e_kᵀ), tabulated for j = 0 .. T − 1.

    ``row[j, k, i]`` = ‖e_iᵀ (M_k/k_o) A_k^j‖; ``col[j, k, i]`` = [A_k^j]_{ik};
    ``norm[j, k]`` ≥ ‖A_k^j‖₂; ``rho[k]`` = ``norm[T − 1, k]`` < 1, ``a_max[k]`` ≥
    sup_j ‖A_k^j‖ and ``tail[k]`` ≥ Σ_{j≥0} ‖A_k^j‖ where ``finite[k]`` (M_k Hurwitz).
    """

    row: np.ndarray
    col: np.ndarray
    norm: np.ndarray
    rho: np.ndarray
    a_max: np.ndarray
    tail: np.ndarray
    finite: np.ndarray

    @property
    def steps(self) -> int:
        return len(self.row)


def observer_tables(
    graph: Graph, ko: float, h: float, decayed: float = 1e-6, max_steps: int = 20000
) -> ObserverTables:
    """Tabulate the powers of A_k for every k of ``graph`` (see :class:`ObserverTables`)."""
    n = graph.n
    idx = np.arange(n)
    p = np.repeat(graph.laplacian()[None], n, axis=0)
    p[idx, idx, idx] += 1.0  # M_k / k_o = L + e_k e_kᵀ
    a = np.eye(n)[None] - (h * ko) * p
    q = np.broadcast_to(np.eye(n), a.shape).copy()  # A_k^j
    # a monitored robot whose M_k is not Hurwitz (graph not strongly connected) has no bound
    finite = np.linalg.eigvals(p).real.min(axis=1) > 1e-12
    rows, cols, norms = [], [], []
    while True:
        rows.append(np.linalg.norm(p, axis=2))
        cols.append(q[idx, :, idx])  # column k of A_k^j
        norms.append(_two_norm_bound(q))
        if len(rows) % 50 == 0 and ((norms[-1][finite] < decayed).all() or len(rows) >= max_steps):
            break
        p = p @ a
        q = q @ a
    norm = np.stack(norms)
    rho = norm[-1]
    if finite.any() and (rho[finite] >= 1.0).any():
        raise ScenarioError(
            f"onboard.thresholds: the observer of this {n}-robot graph decays too slowly for "
            f"{max_steps} tabulated periods; use a better connected graph, a larger ko, or "
            'thresholds = "paper"'
        )
    with np.errstate(divide="ignore"):
        tail = np.where(finite, norm.sum(axis=0) / (1.0 - np.minimum(rho, 0.999999)), np.inf)
    return ObserverTables(np.stack(rows), np.stack(cols), norm, rho, norm.max(axis=0), tail, finite)


class _Tabulated(Thresholds):
    """A rule tabulated as μ[j] (M, M) for the periods j < T after a restart, then a
    constant bound valid for every later period."""

    def __init__(self, max_steps: int = 20000, decayed: float = 1e-6) -> None:
        self.max_steps = int(max_steps)
        self.decayed = float(decayed)

    def reset(self, config: TeamConfig, x_m0: np.ndarray, prior: np.ndarray) -> None:
        """Read h, k_o, η̄, ξ̄ and G, and tabulate the rule on the team's graph."""
        self.h = config.dt
        self.G = np.asarray(config.G, float)
        super().reset(config, x_m0, prior)

    def restart(self, graph: Graph, y0: np.ndarray, t0: float) -> None:
        """Tabulate for ``graph`` from ``t0``, with initial errors bounded by ``y0[k]``."""
        self.graph, self.y0, self.t0 = graph, np.asarray(y0, float), t0
        tables = observer_tables(graph, self.ko, self.h, self.decayed, self.max_steps)
        self._tables = tables
        table, steady = self._tabulate(tables)
        table[:, :, ~tables.finite] = np.inf
        self._table = table
        self._steady_mu = np.where(tables.finite[None, :], steady, np.inf)

    def _tabulate(self, tb: ObserverTables) -> tuple[np.ndarray, np.ndarray]:
        raise NotImplementedError

    def mu(self, t: float) -> np.ndarray:
        """ⁱμ_k(t) (M, M): rows i observe, columns k are monitored."""
        j = max(round((t - self.t0) / self.h), 0)
        return self._table[j] if j < len(self._table) else self._steady_mu


class BlockRow(_Tabulated):
    """The block-row rule (``[onboard] thresholds = "block_row"``).

    A bound when each robot's measurement noise is within η̄ and the drift of
    y_k = x_k − ∫u_k over one control period is within h ξ̄ (``docs/thresholds.md``).
    """

    def _tabulate(self, tb: ObserverTables) -> tuple[np.ndarray, np.ndarray]:
        n, h = self.graph.n, self.h
        noise = self.ko * self.eta_bar + math.sqrt(n) * self.xi_bar
        cum = np.concatenate([np.zeros((1, n, n)), np.cumsum(tb.row, axis=0)])  # Σ_{l<j}
        eye = np.eye(n)
        init = tb.row * self.y0[None, :, None]
        table = np.transpose(init + h * noise * cum[:-1], (0, 2, 1)) + self.eta_bar * eye
        last = tb.row[-1]
        tail = np.where(tb.finite, tb.tail, 0.0)
        steady = (
            last * tb.a_max[:, None] * self.y0[:, None]
            + h * noise * (cum[-1] + last * tail[:, None])
        ).T + self.eta_bar * eye
        self._noise_h = h * noise
        self._norm_cum = np.concatenate([np.zeros((1, n)), np.cumsum(tb.norm, axis=0)])
        return table, steady

    def bracket(self, t: float) -> np.ndarray:
        """‖ỹ*_k(t)‖ ≤ ‖A_k^j‖ y0_k + h(k_o η̄ + √N ξ̄) Σ_{m<j} ‖A_k^m‖ (restart at an exclusion)."""
        tb, j = self._tables, max(round((t - self.t0) / self.h), 0)
        if j < tb.steps:
            out = tb.norm[j] * self.y0 + self._noise_h * self._norm_cum[j]
        else:
            out = tb.rho * tb.a_max * self.y0 + self._noise_h * tb.tail
        return np.where(tb.finite, out, np.inf)


class Drive(_Tabulated):
    """The drive rule (``[onboard] thresholds = "drive"``): the tightest rule here.

    A bound whenever every healthy robot's fault estimate stays within
    ``phi_bar`` [m/s] (and its anti-windup does not act). By default ``phi_bar``
    is the ℓ1 gain of the fault estimator's closed loop on an ideal plant, from
    η (bound η̄) and from a velocity mismatch (bound ξ̄) to φ̂; on a real robot
    its own mismatch adds to it (``docs/thresholds.md``).
    """

    def __init__(
        self, phi_bar: float | None = None, max_steps: int = 20000, decayed: float = 1e-6
    ) -> None:
        super().__init__(max_steps, decayed)
        self.phi_bar_param = phi_bar

    def reset(self, config: TeamConfig, x_m0: np.ndarray, prior: np.ndarray) -> None:
        """Compute Φ̄ (unless given), then tabulate."""
        self.h = config.dt
        self.phi_bar = (
            float(self.phi_bar_param)
            if self.phi_bar_param is not None
            else estimator_gain(config.K, config.G, config.dt, config.eta_bar, config.xi_bar)
        )
        super().reset(config, x_m0, prior)

    def _tabulate(self, tb: ObserverTables) -> tuple[np.ndarray, np.ndarray]:
        n, h, ko = self.graph.n, self.h, self.ko
        # the drive G φ̂_k: measured from φ̂(0) = 0 at the start, from φ̂(t_r) after a restart
        self._drive = np.linalg.norm(self.G, 2) * self.phi_bar * (2.0 if self.t0 > 0 else 1.0)
        c = np.diff(tb.col, axis=0, prepend=0.0)  # c_m = [A^m − A^{m−1}]_{ik}, c_0 = δ_ik
        tv = np.concatenate([np.zeros((1, n, n)), np.cumsum(np.abs(c), axis=0)])  # Σ_{m<t}
        init = tb.row * self.y0[None, :, None]
        table = np.transpose(init + self._drive * tv[:-1], (0, 2, 1))
        # beyond the table: |c_m| = h [M A^{m−1}]_{ik} <= h k_o row[T−1] ‖A^{m−T}‖
        last = tb.row[-1]
        tail = np.where(tb.finite, tb.tail, 0.0)
        steady = (
            last * tb.a_max[:, None] * self.y0[:, None]
            + self._drive * (tv[-1] + h * ko * last * tail[:, None])
        ).T
        return table, steady

    def bracket(self, t: float) -> np.ndarray:
        """A bound of ‖ε_k(t)‖ = ‖(ⁱŷ_k − y_m,k)_i‖ over the team, for the restart at an
        exclusion: ‖A^t‖ ε̄0 + (√N + h k_o Σ_{m<t} ‖A^m‖) ‖G‖ Φ̄ (by parts, as in the rule)."""
        tb, j = self._tables, max(round((t - self.t0) / self.h), 0)
        a_sum = self._norm_sum(j)
        a_t = tb.norm[j] if j < tb.steps else tb.rho * tb.a_max
        out = a_t * self.y0 + (math.sqrt(self.graph.n) + self.h * self.ko * a_sum) * self._drive
        return np.where(tb.finite, out, np.inf)

    def _norm_sum(self, j: int) -> np.ndarray:
        tb = self._tables
        if j < tb.steps:
            return tb.norm[:j].sum(axis=0)
        return tb.tail


def estimator_gain(
    K: np.ndarray, G: np.ndarray, h: float, eta_bar: float, xi_bar: float, steps: int = 100000
) -> float:
    """Bound of ‖φ̂‖ on a healthy robot of an ideal plant (ẋ = ū + ξ, x_m = x + η).

    The fault estimator's closed loop (eqs. 28-31 with compensation) is linear in
    the deviation d = x − z and the integral I = ∫e: φ̂ = G⁻¹(d + η + K I),
    d⁺ = d + h(ξ − φ̂ − K(d + η)), I⁺ = I + h(d + η). Returns
    Σ_t ‖H_η(t)‖₂ η̄ + Σ_t ‖H_ξ(t)‖₂ ξ̄ (ℓ1 norms of its impulse responses).
    """
    K, G = np.asarray(K, float), np.asarray(G, float)
    gi = np.linalg.inv(G)
    n = len(K)
    eye = np.eye(n)
    # state s = [d, I]; φ̂ = C s + D η
    C = np.hstack([gi, gi @ K])
    D = gi
    Ad = np.block(
        [[eye - h * gi - h * K, -h * gi @ K], [h * eye, eye]]
    )  # d⁺ = d − h G⁻¹(d + K I) − h K d + ...
    B_eta = np.vstack([-h * gi - h * K, h * eye])
    B_xi = np.vstack([h * eye, np.zeros((n, n))])
    if np.abs(np.linalg.eigvals(Ad)).max() >= 1.0:
        raise ScenarioError(
            "gains.G, gains.K: the fault estimator's loop is unstable at this control period; "
            'thresholds = "drive" needs it stable'
        )
    total_eta = np.linalg.norm(D, 2)
    total_xi = 0.0
    xe, xx = B_eta.copy(), B_xi.copy()
    for _ in range(steps):
        he, hx = np.linalg.norm(C @ xe, 2), np.linalg.norm(C @ xx, 2)
        total_eta += he
        total_xi += hx
        if max(np.abs(xe).max(), np.abs(xx).max()) < 1e-14:
            break
        xe, xx = Ad @ xe, Ad @ xx
    return float(total_eta * eta_bar + total_xi * xi_bar)


def predicted_delays(
    graph: Graph,
    ko: float,
    h: float,
    mu_steady: np.ndarray,
    fault: float,
    tables: ObserverTables | None = None,
) -> np.ndarray:
    """ⁱΔt_d (M, M) for a constant, uncompensated fault of size ``fault`` [m/s] on robot k.

    Such a fault moves robot k's measured y_m,k by h·fault every period, so by eq. (1)
    of ``docs/thresholds.md`` its signature at robot i after τ = j h is
    ‖ⁱf_k(τ)‖ = h·fault·Σ_{m<j} [A_k^m]_{ik} (non-negative, increasing), and eq. 46
    guarantees detection once it reaches 2 ⁱμ_k (the steady threshold ``mu_steady``).
    +inf where it never does within the tabulated horizon (a stop at the path speed
    may still be detected later, as the team pulls away and its command grows).
    """
    tb = tables or observer_tables(graph, ko, h)
    signature = h * fault * np.cumsum(tb.col, axis=0)  # (T, K, N): after j + 1 periods
    need = 2.0 * np.asarray(mu_steady).T  # (K, N) as [k, i]
    reached = signature >= need[None]
    first = np.where(reached.any(axis=0), reached.argmax(axis=0) + 1, -1)
    delays = np.where(first > 0, first * h, np.inf)
    # past the table the signature only grows towards fault / k_o (its limit, eq. 46)
    return delays.T
