"""κ, λ of eq. 41: the decay of the observer's error matrix for every monitored robot.

:func:`decay_bound` gives κ, λ with ‖e^{−M_k t}‖ ≤ κ e^{−λ t} for one monitored robot k from
the N×N matrix M_k = k_o(L + e_k e_kᵀ) (docs/notes.md, 5-6); :func:`decay_bounds` for
every k, batched through the row and column sums of :mod:`.kernels` at scale. The paper's thresholds
(:mod:`.paper`) are built on them."""

from __future__ import annotations

import functools
import math
import threading
from concurrent.futures import Future

import numpy as np
from scipy.linalg import expm

from ...core.graph import Graph, reaches_all, rotation_invariant
from .kernels import TINY, Adjacency, best_rate, column_of_row, sweep_sums


def decay_bound(m: np.ndarray, n_lambda: int = 49) -> tuple[float, float]:
    """κ, λ > 0 with ‖exp(−M t)‖₂ ≤ κ e^{−λ t} for all t ≥ 0 (eq. 41).

    Any λ below the smallest real part λ_min of M's eigenvalues is valid;
    κ(λ) = sup_t ‖exp(−M t)‖ e^{λ t}. The steady threshold grows with κ/λ, so λ
    is picked on a grid in (0, λ_min) to minimise κ/λ (docs/notes.md, 6). The sup is
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
    """k_o (L + e_k e_kᵀ): ‖exp(−k_o L̃_k t)‖ reduces to this N×N matrix (docs/notes.md, 5)."""
    m = graph.laplacian()
    m[k, k] += 1.0
    return ko * m


#: κ, λ are computed exactly (batched expm and SVDs, ~N³ per monitored robot and time
#: point) while (robots computed) × N³ stays below this; beyond, certified (fast)
EXACT_WORK = 1.1e6


_Key = tuple[int, tuple[tuple[int, int], ...], float, int]


def decay_bounds(graph: Graph, ko: float, n_lambda: int = 49) -> tuple[np.ndarray, np.ndarray]:
    """κ_k, λ_k (eq. 41) for every monitored robot k of ``graph`` (cached per graph).

    See :func:`_decay_bounds`. A graph invariant under the rotation i -> i + 1
    (rings, rings with chords: every robot sees the same graph) needs only k = 0.
    The last graphs are cached, so campaign workers and reset runs pay once; a graph
    :func:`prefetch_decay_bounds` began is taken from its helper thread (waiting for it if need be).
    """
    key = _key(graph, ko, n_lambda)
    pending = _PENDING.pop(key, None)
    kappa, lam = pending.result() if pending is not None else _cached_decay_bounds(*key)
    return kappa.copy(), lam.copy()


def decay_bound_of(graph: Graph, ko: float, k: int, n_lambda: int = 49) -> tuple[float, float]:
    """κ_k, λ_k (eq. 41) of one monitored robot ``k``: :func:`decay_bounds`'s entry where
    all of them are cheap (a small graph, a rotation-invariant one) or already begun;
    otherwise the certified sweep of that robot's column alone, so that a large team does
    not pay for every robot when one is asked for."""
    key = _key(graph, ko, n_lambda)
    if key in _PENDING or _cheap(graph):
        kappa, lam = decay_bounds(graph, ko, n_lambda)
        return float(kappa[k]), float(lam[k])
    return _cached_decay_bound_of(*key, k)


def _cheap(graph: Graph) -> bool:
    """Whether every robot's κ, λ together cost about as much as one robot's."""
    return rotation_invariant(graph) or graph.n * graph.n**3 <= EXACT_WORK


@functools.lru_cache(maxsize=64)
def _cached_decay_bound_of(
    n: int, edges: tuple[tuple[int, int], ...], ko: float, n_lambda: int, k: int
) -> tuple[float, float]:
    kappa, lam = _decay_bounds_fast(Graph(n, edges), ko, n_lambda, only=np.array([k]))
    return float(kappa[0]), float(lam[0])


def prefetch_decay_bounds(graph: Graph, ko: float, n_lambda: int = 49) -> None:
    """Begin :func:`decay_bounds` of ``graph`` on a helper thread, for a set-up that has
    other work to do before it needs them (the simulation builds its scene meanwhile).
    The certified sweep runs compiled without the GIL (:func:`.kernels.sweep_sums`), so
    the two share the cores; the numbers are the same either way. The thread is a daemon:
    a process interrupted during its set-up does not wait for it to finish."""
    key = _key(graph, ko, n_lambda)
    if key in _PENDING:
        return
    if len(_PENDING) >= 4:  # begun and never asked for: their results stay in the cache
        _PENDING.clear()
    future: Future = Future()

    def work() -> None:
        try:
            future.set_result(_cached_decay_bounds(*key))
        except BaseException as exc:  # raised where decay_bounds takes it
            future.set_exception(exc)

    threading.Thread(target=work, name="dftc-kappa-lambda", daemon=True).start()
    _PENDING[key] = future


def _key(graph: Graph, ko: float, n_lambda: int) -> _Key:
    """What κ, λ depend on: the graph's size and edges, k_o and the λ grid."""
    return graph.n, tuple(sorted(graph.edges)), float(ko), n_lambda


#: decay_bounds begun by prefetch_decay_bounds and not yet taken
_PENDING: dict[_Key, Future] = {}


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
    s_a, s_u, settled = np.empty(kk), np.empty(kk), np.empty(kk, dtype=np.bool_)
    while len(cols):
        # the chunks run compiled until a column settles (sweep_sums); its maxima by block
        rows = chunk * max(1, min(256, (1 << 20) // (len(cols) * chunk)))
        amax, umax = np.empty((rows, len(cols))), np.empty((rows, len(cols)))
        steps_done, work, rows = sweep_sums(
            a, a2, u, u2, adj.src, adj.first, adj.dst, adj.out_first, adj.deg,
            column_of_row(ks[cols], n), beta, chunk, settle, steps_done, max_steps, work,
            max_work, amax, umax, s_a, s_u, settled,
        )  # fmt: skip
        for hist, m in ((hist_a, amax), (hist_u, umax)):
            full = np.full((rows, kk), np.nan)
            full[:, cols] = m[:rows]
            hist.append(full)
        if not settled[: len(cols)].any():
            continue
        na_all, nu_all = np.concatenate(hist_a), np.concatenate(hist_u)
        slack = (np.arange(len(na_all)) + 1.0) * TINY  # the flushed subnormals
        for pos in np.flatnonzero(settled[: len(cols)]):
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
        keep = ~settled[: len(cols)]
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
