"""Fault detection, isolation and recovery (eqs. 39-43, Remark 5.2).

* :func:`decay_bound` gives κ, λ of eq. 41 for one monitored robot k, from the
  N×N matrix k_o(L + e_k e_kᵀ) (NOTES 5-6).
* :class:`Thresholds` (block) evaluates the adaptive thresholds ⁱμ_k(t) of eq. 40.
* :class:`Decision` (block) raises robot i's flag on robot k when ‖ⁱr_k‖ > ⁱμ_k
  has held for ``window`` seconds (Remark 5.2), and lowers it after as long
  below; the rule is the compiled :func:`decide`.

The exclusion protocol (eqs. 42-43) lives in :mod:`dftc_mujoco.onboard.team`,
which owns the vectors that are resized.
"""

from __future__ import annotations

import functools
import math

import numpy as np
from numba import njit
from scipy.linalg import expm

from ..graph import Graph
from .block import Block, TeamConfig
from .columns import (
    TINY,
    Adjacency,
    advance_sums,
    best_rate,
    column_of_row,
    ratios,
    reaches_all,
    rotation_invariant,
)


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


def decay_bounds(graph: Graph, ko: float, n_lambda: int = 49) -> tuple[np.ndarray, np.ndarray]:
    """κ_k, λ_k (eq. 41) for every monitored robot k of ``graph`` (cached per graph).

    See :func:`_decay_bounds`. A graph invariant under the rotation i -> i + 1
    (rings, rings with chords: every robot sees the same graph) needs only k = 0.
    The last graphs are cached, so campaign workers and reset runs pay once.
    """
    kappa, lam = _cached_decay_bounds(graph.n, tuple(sorted(graph.edges)), float(ko), n_lambda)
    return kappa.copy(), lam.copy()


#: κ, λ are computed exactly (batched expm and SVDs, ~N³ per monitored robot and time
#: point) while (robots computed) × N³ stays below this; beyond, certified (fast)
EXACT_WORK = 1.1e6


@functools.lru_cache(maxsize=16)
def _cached_decay_bounds(
    n: int, edges: tuple[tuple[int, int], ...], ko: float, n_lambda: int
) -> tuple[np.ndarray, np.ndarray]:
    graph = Graph(n, edges)
    circulant = rotation_invariant(graph)  # M_k = R^k M_0 R^-k, same norms
    only = np.array([0]) if circulant else None
    count = 1 if circulant else n
    method = _decay_bounds if count * n**3 <= EXACT_WORK else _decay_bounds_fast
    kappa, lam = method(graph, ko, n_lambda, only=only)
    if circulant:
        return np.full(n, kappa[0]), np.full(n, lam[0])
    return kappa, lam


def _decay_bounds_fast(
    graph: Graph,
    ko: float,
    n_lambda: int = 49,
    only: np.ndarray | None = None,
    settle: float = 0.02,
    max_steps: int = 20_000,
    max_work: float = 4e9,
) -> tuple[np.ndarray, np.ndarray]:
    """Certified κ_k, λ_k (eq. 41) for every monitored robot k (or those in ``only``),
    from vector recursions only: no matrix exponential, no SVD.

    With q = k_o (d_max + 1), B_k = I − M_k/q ≥ 0 and e^{−M_k t} = Σ_n Pois(n; q t) B_k^n
    (uniformization), all terms non-negative. If ‖B_k^n‖_∞ ≤ κ_∞ σ^n and
    ‖B_k^n‖₁ ≤ κ₁ σ^n for every n with σ = 1 − λ/q, then ‖e^{−M_k t}‖_∞ ≤ κ_∞ e^{−λt},
    the same for ‖·‖₁, and ‖e^{−M_k t}‖₂ ≤ √(‖·‖₁‖·‖_∞) ≤ √(κ₁ κ_∞) e^{−λt} = κ e^{−λt}.
    ‖B^n‖_∞ and ‖B^n‖₁ are the largest row and column sums: the recursions a ← B a,
    u ← Bᵀ u from 1, batched over k. Each stops at T once the Collatz-Wielandt bracket
    of its decay rate is within ``settle`` (min_i and max_i of a_{T+1}/a_T, u_{T+1}/u_T), or
    after ``max_work`` entry updates as soon as s_a, s_u < 1 (valid, looser); then
    B a_T ≤ s_a a_T gives ‖B^{T+m}‖_∞ ≤ s_a^m ‖B^T‖_∞ (B ≥ 0), and likewise s_u, so
    every λ ≤ λ_cert = q (1 − max(s_a, s_u)) ≤ λ_min is certified with the maxima over
    n ≤ T. λ is picked on a grid in (0, λ_cert] to minimise κ/λ. κ is an upper bound
    of the exact one (by √(‖·‖₁‖·‖_∞) ≥ ‖·‖₂), still a valid eq. 41 bound.
    """
    n = graph.n
    idx = np.arange(n) if only is None else np.asarray(only)
    kappa = np.full(len(idx), np.inf)
    lam = np.zeros(len(idx))
    good = np.flatnonzero(reaches_all(graph)[idx])
    if not len(good):
        return kappa, lam
    adj = Adjacency.of(graph)
    q = ko * (adj.deg.max() + 1.0)
    beta = ko / q
    ks = idx[good]
    kk = len(ks)
    a, a2 = np.ones((n, kk)), np.empty((n, kk))
    u, u2 = np.ones((n, kk)), np.empty((n, kk))
    cols = np.arange(kk)
    hist_a: list[np.ndarray] = [np.ones((1, kk))]  # ‖B^n‖_∞ per n (rows) and robot
    hist_u: list[np.ndarray] = [np.ones((1, kk))]  # ‖B^n‖₁
    fractions = np.linspace(0.02, 1.0, n_lambda)
    steps_done, chunk, work = 0, 16, 0.0
    while len(cols):
        amax, umax = np.empty((chunk, len(cols))), np.empty((chunk, len(cols)))
        advance_sums(
            a, a2, u, u2, adj.src, adj.first, adj.dst, adj.out_first, adj.deg,
            column_of_row(ks[cols], n), beta, chunk, amax, umax,
        )  # fmt: skip
        for hist, m in ((hist_a, amax), (hist_u, umax)):
            full = np.full((chunk, kk), np.nan)
            full[:, cols] = m
            hist.append(full)
        steps_done += chunk
        # chunk is even: the newest sums are in a, u and the previous ones in a2, u2
        ra, ru = ratios(a, a2), ratios(u, u2)
        s_a, s_u = ra.max(axis=0), ru.max(axis=0)
        settled = (
            (1.0 - s_a >= (1.0 - settle) * (1.0 - ra.min(axis=0)))
            & (1.0 - s_u >= (1.0 - settle) * (1.0 - ru.min(axis=0)))
            & (s_a < 1.0)
            & (s_u < 1.0)
        )
        # past the budget any certificate with s < 1 is valid, only looser (λ_cert lower)
        work += 2 * chunk * len(cols) * (n + len(adj.src))
        if work > max_work:
            settled |= (s_a < 1.0) & (s_u < 1.0)
        if steps_done >= max_steps:
            settled[:] = True
        if not settled.any():
            continue
        na_all, nu_all = np.concatenate(hist_a), np.concatenate(hist_u)
        slack = (np.arange(len(na_all)) + 1.0) * TINY  # the flushed subnormals
        for pos in np.flatnonzero(settled):
            c = cols[pos]
            lam_cert = q * (1.0 - max(s_a[pos], s_u[pos]))
            if lam_cert > 0:
                k_, l_ = best_rate(
                    np.log(na_all[:, c] + slack), np.log(nu_all[:, c] + slack), q, lam_cert,
                    fractions,
                )  # fmt: skip
            else:  # not settled within max_steps: the exact method for this robot
                k_, l_ = decay_bound(observer_matrix(graph, ko, int(ks[c])), n_lambda)
            kappa[good[c]], lam[good[c]] = k_ * (1.0 + 1e-9), l_
        keep = ~settled
        a, a2, u, u2 = (np.ascontiguousarray(x[:, keep]) for x in (a, a2, u, u2))
        cols = cols[keep]
    return kappa, lam


def _decay_bounds(
    graph: Graph, ko: float, n_lambda: int = 49, only: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """κ_k, λ_k (eq. 41) for every monitored robot k of ``graph`` (or those in ``only``).

    Same definition as :func:`decay_bound` (λ on a grid below λ_min minimising
    κ/λ, κ the sup of ‖exp(−M_k t)‖ e^{λt}), computed for all k at once so that
    it stays cheap at N = 100: a time grid normalised by each λ_min (64 uniform
    points up to 4/λ_min built by repeated multiplication with one batched
    expm, then 7 doublings by squaring), the 2-norm by warm-started batched
    power iteration, an exact SVD at each peak (a second pass over the same
    recurrence), and a 1e-3 relative safety margin so that κ bounds the
    continuous sup.
    """
    n = graph.n
    lap = graph.laplacian()
    idx = np.arange(n) if only is None else np.asarray(only)
    m = np.repeat(lap[None] * ko, len(idx), axis=0)
    m[np.arange(len(idx)), idx, idx] += ko  # M_k = k_o (L + e_k e_kᵀ)
    lam_min = np.linalg.eigvals(m).real.min(axis=1)
    kappa = np.full(len(idx), np.inf)
    lam = np.zeros(len(idx))
    good = np.flatnonzero(lam_min > 1e-9)
    if len(good) == 0:
        return kappa, lam
    mk, lk = m[good], lam_min[good]
    uniform = 64
    tau = np.concatenate([np.linspace(0.0, 4.0, uniform), 4.0 * 2.0 ** np.arange(1, 8)])
    step = expm(-mk * (tau[1] / lk)[:, None, None])
    e = np.broadcast_to(np.eye(n), mk.shape).copy()
    norms = np.empty((len(good), len(tau)))
    v = np.random.default_rng(0).standard_normal((len(good), n))
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    for j in range(len(tau)):
        if j > 0:
            e = e @ step if j < uniform else e @ e
        norms[:, j], v = _top_singular(e, v)
    t = tau[None, :] / lk[:, None]  # (K, T)
    lams = lk[:, None] * np.linspace(0.02, 0.98, n_lambda)[None, :]  # (K, L)
    prod = norms[:, None, :] * np.exp(lams[:, :, None] * t[:, None, :])  # (K, L, T)
    kap = prod.max(axis=2)
    inside = prod.argmax(axis=2) < len(tau) - 1
    ratio = np.where(inside, kap / lams, np.inf)
    best = ratio.argmin(axis=1)
    rows = np.arange(len(good))
    at = prod[rows, best].argmax(axis=1)
    # second pass over the same recurrence: an exact 2-norm where each k peaks
    exact = np.empty(len(good))
    e = np.broadcast_to(np.eye(n), mk.shape).copy()
    for j in range(at.max() + 1):
        if j > 0:
            e = e @ step if j < uniform else e @ e
        hit = np.flatnonzero(at == j)
        if len(hit):
            exact[hit] = np.linalg.norm(e[hit], ord=2, axis=(1, 2))
    peak = np.maximum(kap[rows, best], exact * np.exp(lams[rows, best] * t[rows, at]))
    kappa[good] = peak * (1.0 + 1e-3)
    lam[good] = lams[rows, best]
    return kappa, lam


def _top_singular(a: np.ndarray, v: np.ndarray, iters: int = 30) -> tuple[np.ndarray, np.ndarray]:
    """Largest singular value of each matrix in the stack ``a`` (K, N, N), by power
    iteration on aᵀa started from ``v`` (K, N); returns the values and the vectors."""
    at = np.swapaxes(a, 1, 2)
    v = v[..., None]
    for _ in range(iters):
        w = at @ (a @ v)  # batched matrix-vector products (BLAS), not einsum
        v = w / np.maximum(np.linalg.norm(w, axis=1, keepdims=True), 1e-300)
    return np.linalg.norm((a @ v)[..., 0], axis=1), v[..., 0]


@njit(cache=True)
def eq40(start, steady, lam, elapsed, coef, eta, out):  # pragma: no cover - compiled
    """ⁱμ_k(t) = (√n dᵢ + δᵢₖ)·‖ỹ*_k‖-bound + δᵢₖ η̄ into ``out`` (M, M) (eq. 40).

    The bound of ‖ỹ*_k(t)‖ is ‖ỹ*_k(0)‖ κ e^{−λt} + κ(k_o η̄ + √N ξ̄)/λ (1 − e^{−λt})
    with ``start`` = κ‖ỹ*_k(0)‖ and ``steady`` = κ(k_o η̄ + √N ξ̄)/λ; where λ_k = 0
    (no bound: the graph is not strongly connected) the threshold is +inf.
    """
    for k in range(out.shape[1]):
        if lam[k] > 0:
            decay = np.exp(-lam[k] * elapsed)
            b = start[k] * decay + steady[k] * (1.0 - decay)
            for i in range(out.shape[0]):
                out[i, k] = coef[i, k] * b + eta[i, k]
        else:
            for i in range(out.shape[0]):
                out[i, k] = np.inf


class Thresholds(Block):
    """The paper's adaptive thresholds ⁱμ_k(t) (eqs. 40-41) for every robot i and robot k.

    Restarted at each exclusion from a bound valid at that instant, with κ, λ
    of the new graph (NOTES 7). Override :meth:`mu` (and :meth:`restart`) to try
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
        from ..mission import polygon_offsets
        from ..scenario import Formation

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
        """Start anew at ``t0`` on ``graph`` with ‖ỹ*_k(t0)‖ ≤ ``y0[k]`` (NOTES 7)."""
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
        eq40(self._start, self._steady_f, self.lam, elapsed, self._coef, self._eta, self._mu_buf)
        return self._mu_buf


@njit(cache=True)
def decide(r_norm, mu, above, below, flag, dt, window, exclusive, raised):  # pragma: no cover
    """Robot i flags k once ‖ⁱr_k‖ > ⁱμ_k has held ``window`` s; lowers it after as long below.

    Updates the timers ``above``, ``below`` and ``flag`` (M, M) in place (eq. 39 with
    Remark 5.2's window); ``raised`` (M, M) marks the flags raised now. Returns
    how many were raised. With ``exclusive`` (eq. 39's second clause) robot i counts
    ‖ⁱr_k‖ > ⁱμ_k only while all its other residuals stay at or below their thresholds.
    """
    count = 0
    for i in range(r_norm.shape[0]):
        n_over = 0
        if exclusive:
            for k in range(r_norm.shape[1]):
                if r_norm[i, k] > mu[i, k]:
                    n_over += 1
        for k in range(r_norm.shape[1]):
            raised[i, k] = False
            if r_norm[i, k] > mu[i, k] and not (exclusive and n_over > 1):
                above[i, k] += dt
                below[i, k] = 0.0
                if not flag[i, k] and above[i, k] >= window - 1e-9:
                    flag[i, k] = True
                    raised[i, k] = True
                    count += 1
            else:
                above[i, k] = 0.0
                below[i, k] += dt
                if flag[i, k] and below[i, k] >= window - 1e-9:
                    flag[i, k] = False
    return count


class Decision(Block):
    """Debounced flags: robot i flags k after ``window`` s above ⁱμ_k (eq. 39, Remark 5.2).

    ``window`` defaults to the scenario's ``fdir.detection_window`` and
    ``isolation`` to ``fdir.isolation``: ``"pairwise"`` (robot i judges each k on
    its own) or ``"exclusive"`` (eq. 39's second clause: robot i isolates k only
    while its other residuals stay below their thresholds). Override
    :meth:`update` to try another decision rule; row i may use only robot i's
    own residuals and thresholds.
    """

    kind = "decision"

    def __init__(self, window: float | None = None, isolation: str | None = None) -> None:
        self.window_param = window
        self.isolation_param = isolation

    def reset(self, config: TeamConfig, x_m0: np.ndarray, prior: np.ndarray) -> None:
        """All timers at zero, nobody flagged."""
        self.dt = config.dt
        self.window = config.detection_window if self.window_param is None else self.window_param
        isolation = config.isolation if self.isolation_param is None else self.isolation_param
        if isolation not in ("pairwise", "exclusive"):
            raise ValueError(f"isolation must be 'pairwise' or 'exclusive', got {isolation!r}")
        self.exclusive = isolation == "exclusive"
        n = len(x_m0)
        self.above = np.zeros((n, n))
        self.below = np.zeros((n, n))
        self.flag = np.zeros((n, n), bool)
        self._raised = np.zeros((n, n), bool)

    @classmethod
    def standalone(cls, n: int, window: float, dt: float) -> Decision:
        """A decision block for ``n`` robots outside any team."""
        d = cls(window)
        d.dt, d.window, d.exclusive = dt, window, False
        d.above, d.below = np.zeros((n, n)), np.zeros((n, n))
        d.flag, d._raised = np.zeros((n, n), bool), np.zeros((n, n), bool)
        return d

    def update(self, r_norm: np.ndarray, mu: np.ndarray) -> np.ndarray:
        """Feed ‖ⁱr_k‖ and ⁱμ_k (M, M); return the flags raised at this instant (M, M) bool."""
        decide(
            np.ascontiguousarray(r_norm, float),
            np.ascontiguousarray(mu, float),
            self.above,
            self.below,
            self.flag,
            self.dt,
            self.window,
            self.exclusive,
            self._raised,
        )
        return self._raised

    def drop(self, p: int, graph: Graph, t: float) -> None:
        """Forget robot at position ``p`` (vectors resized after an exclusion)."""
        for name in ("above", "below", "flag", "_raised"):
            a = getattr(self, name)
            setattr(self, name, np.delete(np.delete(a, p, axis=0), p, axis=1))
