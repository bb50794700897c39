"""Fault detection, isolation and recovery (eqs. 39-43, Remark 5.2).

* :func:`decay_bound` gives κ, λ of eq. 41 for one monitored robot k, from the
  N×N matrix k_o(L + e_k e_kᵀ) (NOTES 5-6).
* :class:`Thresholds` evaluates the adaptive thresholds ⁱμ_k(t) of eq. 40.
* :class:`Decision` raises robot i's flag on robot k when ‖ⁱr_k‖ > ⁱμ_k has
  held for ``window`` seconds (Remark 5.2), and lowers it after as long below.

The exclusion protocol (eqs. 42-43) lives in :mod:`dftc_mujoco.onboard.team`,
which owns the vectors that are resized.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.linalg import expm

from ..graph import Graph


def decay_bound(m: np.ndarray, n_lambda: int = 49) -> tuple[float, float]:
    """κ, λ > 0 with ‖exp(−M t)‖₂ ≤ κ e^{−λ t} for all t ≥ 0 (eq. 41).

    Any λ below the smallest real part λ_min of M's eigenvalues is valid;
    κ(λ) = sup_t ‖exp(−M t)‖ e^{λ t}. The steady threshold grows with κ/λ, so λ
    is picked on a grid in (0, λ_min) to minimise κ/λ (NOTES 6). The sup is
    taken on a time grid dense up to 4/λ_min and geometric up to 400/λ_min,
    refined around its peak, and multiplied by 1 + 1e-4 so that κ bounds the
    continuous sup rather than approximating it from below.
    Returns (inf, 0) when M is not positive stable (graph not strongly connected).
    """
    lam_min = float(np.linalg.eigvals(m).real.min())
    if lam_min <= 1e-9:
        return math.inf, 0.0
    horizon = 4.0 / lam_min
    t = np.concatenate(
        [np.linspace(0.0, horizon, 160), np.geomspace(horizon, 100 * horizon, 120)[1:]]
    )
    step = expm(-m * t[1])
    norms = np.empty(len(t))
    e = np.eye(len(m))
    for j in range(160):  # uniform part: powers of one step
        norms[j] = np.linalg.norm(e, 2)
        e = e @ step
    for j in range(160, len(t)):
        norms[j] = np.linalg.norm(expm(-m * t[j]), 2)
    lams = lam_min * np.linspace(0.02, 0.98, n_lambda)
    prod = norms[None, :] * np.exp(lams[:, None] * t[None, :])
    kappa = prod.max(axis=1)
    inside = prod.argmax(axis=1) < len(t) - 1  # the sup was reached inside the grid
    ratio = np.where(inside, kappa / lams, np.inf)
    best = int(np.argmin(ratio))
    lam = float(lams[best])
    j = int(prod[best].argmax())
    fine = np.linspace(t[max(j - 1, 0)], t[min(j + 1, len(t) - 1)], 64)
    peak = max(np.linalg.norm(expm(-m * tt), 2) * np.exp(lam * tt) for tt in fine)
    return max(float(kappa[best]), float(peak)) * (1.0 + 1e-4), lam


def observer_matrix(graph: Graph, ko: float, k: int) -> np.ndarray:
    """k_o (L + e_k e_kᵀ): ‖exp(−k_o L̃_k t)‖ reduces to this N×N matrix (NOTES 5)."""
    m = graph.laplacian()
    m[k, k] += 1.0
    return ko * m


def decay_bounds(graph: Graph, ko: float) -> tuple[np.ndarray, np.ndarray]:
    """κ_k, λ_k (eq. 41) for every monitored robot k of ``graph``."""
    pairs = [decay_bound(observer_matrix(graph, ko, k)) for k in range(graph.n)]
    return np.array([p[0] for p in pairs]), np.array([p[1] for p in pairs])


@dataclass
class Thresholds:
    """ⁱμ_k(t) of eq. 40 for a team, restarted at ``t0`` with ‖ỹ*_k(t0)‖ ≤ ``y0[k]``."""

    graph: Graph
    ko: float
    eta_bar: float
    xi_bar: float
    y0: np.ndarray  # (N,)
    t0: float = 0.0
    n_dim: int = 2
    kappa: np.ndarray = field(init=False)
    lam: np.ndarray = field(init=False)

    def __post_init__(self) -> None:
        self.kappa, self.lam = decay_bounds(self.graph, self.ko)
        n = self.graph.n
        eye = np.eye(n)
        self._coef = np.sqrt(self.n_dim) * self.graph.in_degree()[:, None] + eye  # √n dᵢ + δᵢₖ
        self._eta = self.eta_bar * eye  # δᵢₖ η̄
        with np.errstate(divide="ignore", invalid="ignore"):
            self._steady = np.where(
                self.lam > 0,
                self.kappa * (self.ko * self.eta_bar + np.sqrt(n) * self.xi_bar) / self.lam,
                np.inf,
            )
        # after this long every transient term of eq. 40 is below 1e-12 of its start
        finite = self.lam[self.lam > 0]
        self._settled = self.t0 + (28.0 / finite.min() if len(finite) else np.inf)
        self._mu_steady: np.ndarray | None = None

    def bracket(self, t: float) -> np.ndarray:
        """‖ỹ*_k(0)‖ κ e^{−λt} + κ(k_o η̄ + √N ξ̄)/λ (1 − e^{−λt}), per k: bounds ‖ỹ*_k(t)‖."""
        decay = np.exp(-self.lam * max(t - self.t0, 0.0))
        with np.errstate(invalid="ignore"):
            b = self.y0 * self.kappa * decay + self._steady * (1.0 - decay)
        return np.where(self.lam > 0, b, np.inf)

    def mu(self, t: float) -> np.ndarray:
        """ⁱμ_k(t) for every observer i (rows) and monitored robot k (columns) (eq. 40).

        Where no bound exists (λ_k = 0: the graph is not strongly connected) the
        threshold is +inf: robot k cannot be judged.
        """
        if t >= self._settled:
            if self._mu_steady is None:
                self._mu_steady = self._mu(self.bracket(t))
            return self._mu_steady
        return self._mu(self.bracket(t))

    def _mu(self, b: np.ndarray) -> np.ndarray:
        if np.isinf(b).any():
            return np.where(
                np.isinf(b)[None, :],
                np.inf,
                self._coef * np.where(np.isinf(b), 0.0, b)[None, :] + self._eta,
            )
        return self._coef * b[None, :] + self._eta


@dataclass
class Decision:
    """Debounced flags: robot i flags k after ``window`` s above ⁱμ_k (Remark 5.2)."""

    n: int
    window: float
    dt: float
    above: np.ndarray = field(init=False)
    below: np.ndarray = field(init=False)
    flag: np.ndarray = field(init=False)

    def __post_init__(self) -> None:
        self.above = np.zeros((self.n, self.n))
        self.below = np.zeros((self.n, self.n))
        self.flag = np.zeros((self.n, self.n), bool)

    def update(self, r_norm: np.ndarray, mu: np.ndarray) -> np.ndarray:
        """Feed ‖ⁱr_k‖ and ⁱμ_k (N, N); return the flags raised at this instant (eq. 39)."""
        over = r_norm > mu
        self.above = np.where(over, self.above + self.dt, 0.0)
        self.below = np.where(over, 0.0, self.below + self.dt)
        eps = 1e-9
        raised = ~self.flag & over & (self.above >= self.window - eps)
        lowered = self.flag & ~over & (self.below >= self.window - eps)
        self.flag = (self.flag | raised) & ~lowered
        return raised

    def drop(self, p: int) -> None:
        """Forget robot at position ``p`` (vectors resized after an exclusion)."""
        for name in ("above", "below", "flag"):
            a = getattr(self, name)
            setattr(self, name, np.delete(np.delete(a, p, axis=0), p, axis=1))
        self.n -= 1
