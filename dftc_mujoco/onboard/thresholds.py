"""Threshold rules beside the paper's eq. 40, derived for the discrete-time observer.

``docs/thresholds.md`` has the derivation. In short: with the observer run by
forward Euler at the control period h, A_k = I − h M_k, M_k = k_o(L + e_k e_kᵀ),
the residual block of robot k at robot i is exactly

    ⁱr_k(t) = −[(M_k/k_o) A_k^t]_{i,:} ỹ_k(0)
              − Σ_{j<t} [(M_k/k_o) A_k^j]_{i,:} (k_o h e_k η_k − 1_N w_k)(t−1−j) + δ_ik η_k(t)

where w_k is the drift of y_k = x_k − ∫u_k over one period. With ‖η_k‖ ≤ η̄ and
‖w_k‖ ≤ h ξ̄ it is bounded by the *block-row* rule

    ⁱμ_k(t) = ‖e_iᵀ(M_k/k_o)A_k^t‖ y0_k + h(k_o η̄ + √N ξ̄) Σ_{j<t} ‖e_iᵀ(M_k/k_o)A_k^j‖ + δ_ik η̄,

the discrete-time form of the bound in issue 10 (eq. 40 bounds the same
product by a product of norms, and grows with κ/λ). The row norms are tabulated
once per graph (batched over k) until A_k^t has decayed below 1e-6; past the
table a rigorous tail bound is used.
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import ScenarioError
from ..graph import Graph
from .block import TeamConfig
from .fdir import Thresholds


def _two_norm_bound(q: np.ndarray) -> np.ndarray:
    """‖Q‖₂ ≤ √(‖Q‖₁ ‖Q‖_∞) for each matrix of the stack ``q`` (K, N, N)."""
    a = np.abs(q)
    return np.sqrt(a.sum(axis=1).max(axis=1) * a.sum(axis=2).max(axis=1))


class BlockRow(Thresholds):
    """The block-row threshold rule (``[onboard] thresholds = "block_row"``).

    Valid (a bound, not an estimate) when each robot's measurement noise is
    within η̄ and the drift of y_k = x_k − ∫u_k over one control period is
    within h ξ̄; ``docs/thresholds.md`` derives it and says what that
    assumption means with compensation and actuator lag.
    ``max_steps`` caps the table (the set-up grows with N³ per step).
    """

    def __init__(self, max_steps: int = 20000, decayed: float = 1e-6) -> None:
        self.max_steps = int(max_steps)
        self.decayed = float(decayed)

    def reset(self, config: TeamConfig, x_m0: np.ndarray, prior: np.ndarray) -> None:
        """Read h, k_o, η̄, ξ̄ and tabulate the rule on the team's graph."""
        self.h = config.dt
        super().reset(config, x_m0, prior)

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
    ) -> BlockRow:
        """The rule on ``graph`` outside any team (control period ``dt``)."""
        th = cls()
        th.h = dt
        th.ko, th.eta_bar, th.xi_bar, th.n_dim = ko, eta_bar, xi_bar, n_dim
        th.restart(graph, np.asarray(y0, float), t0)
        return th

    def restart(self, graph: Graph, y0: np.ndarray, t0: float) -> None:
        """Tabulate the row norms for ``graph``, starting at ``t0`` with ‖ỹ*_k(t0)‖ ≤ y0[k]."""
        self.graph, self.y0, self.t0 = graph, np.asarray(y0, float), t0
        n, h, ko = graph.n, self.h, self.ko
        lap = graph.laplacian()
        idx = np.arange(n)
        p = np.repeat(lap[None], n, axis=0)
        p[idx, idx, idx] += 1.0  # (M_k / k_o) for every k: L + e_k e_kᵀ
        a = np.eye(n)[None] - (h * ko) * p  # A_k = I − h M_k
        q = np.broadcast_to(np.eye(n), a.shape).copy()  # A_k^j
        # a monitored robot whose M_k is not Hurwitz (graph not strongly connected) has no bound
        finite = np.linalg.eigvals(h * ko * p).real.min(axis=1) > 1e-12
        rows, bounds = [], []
        steps = 0
        while True:
            rows.append(np.linalg.norm(p, axis=2))  # ‖e_iᵀ (M_k/k_o) A_k^j‖ (K, N)
            bounds.append(_two_norm_bound(q))
            steps += 1
            if steps % 50 == 0:
                if (bounds[-1][finite] < self.decayed).all() or steps >= self.max_steps:
                    break
            p = p @ a
            q = q @ a
        rho = bounds[-1]  # ‖A_k^T‖ bound at the last tabulated step
        if finite.any() and (rho[finite] >= 1.0).any():
            raise ScenarioError(
                f"onboard.thresholds: block_row: the observer of this {n}-robot graph decays "
                f"too slowly for {self.max_steps} tabulated periods; use a faster graph, "
                "a larger ko, or thresholds = \"paper\""
            )
        r = np.stack(rows)  # (T, K, N): row norms
        sum_a = np.sum(bounds, axis=0)  # Σ_{m<T} ‖A^m‖ per k
        a_max = np.max(bounds, axis=0)  # sup_m ‖A^m‖ per k (ρ < 1 beyond)
        with np.errstate(divide="ignore"):
            tail = np.where(finite, sum_a / (1.0 - np.minimum(rho, 0.999999)), np.inf)
        cum = np.concatenate([np.zeros((1, n, n)), np.cumsum(r, axis=0)])  # Σ_{l<j}
        noise = ko * self.eta_bar + math.sqrt(n) * self.xi_bar
        eye = np.eye(n)
        # μ[j, i, k] for j < T, then a bound valid for every later step
        init = r * self.y0[None, :, None]
        self._table = np.transpose(init + h * noise * cum[:-1], (0, 2, 1)) + self.eta_bar * eye
        last = r[-1]  # (K, N)
        tail = np.where(finite, tail, 0.0)  # (no bound there: set to inf below)
        steady = (
            last * a_max[:, None] * self.y0[:, None]
            + h * noise * (cum[-1] + last * tail[:, None])
        ).T + self.eta_bar * eye
        self._steady_mu = np.where(finite[None, :], steady, np.inf)
        self._table[:, :, ~finite] = np.inf
        self._steps = len(r)
        self._finite = finite
        self._norms = np.stack(bounds)  # (T, K): bounds of ‖A_k^j‖
        self._norms_cum = np.concatenate([np.zeros((1, n)), np.cumsum(self._norms, axis=0)])
        self._rho, self._a_max, self._tail = rho, a_max, np.where(finite, tail, np.inf)
        self._noise_h = h * noise

    def mu(self, t: float) -> np.ndarray:
        """ⁱμ_k(t) (M, M): rows i observe, columns k are monitored (the block-row rule)."""
        j = int(round((t - self.t0) / self.h))
        if j < 0:
            j = 0
        return self._table[j] if j < self._steps else self._steady_mu

    def bracket(self, t: float) -> np.ndarray:
        """A bound of ‖ỹ*_k(t)‖ per k (restart value at an exclusion):
        ‖A_k^j‖ y0_k + h(k_o η̄ + √N ξ̄) Σ_{m<j} ‖A_k^m‖, from the same tables."""
        j = max(int(round((t - self.t0) / self.h)), 0)
        if j < self._steps:
            out = self._norms[j] * self.y0 + self._noise_h * self._norms_cum[j]
        else:
            out = self._rho * self._a_max * self.y0 + self._noise_h * self._tail
        return np.where(self._finite, out, np.inf)
