"""Vector recursions on the observer matrices, batched over the monitored robots.

Every monitored robot k has its own matrix M_k = k_o(L + e_k e_kᵀ) (docs/notes.md, 5). The
threshold rules (``docs/thresholds.md``) and the fast κ, λ of eq. 41 need only
vectors pushed through B_k = I − β(L + e_k e_kᵀ), never B_k's powers:

* the columns c = B_k^j e_k (with β = h k_o, B_k is the discrete observer's A_k),
* the row sums B_k^j 1 and the column sums (B_kᵀ)^j 1 (κ, λ with β = k_o / q).

Arrays are laid out (N, K): row i, one column per monitored robot (``rows[b]`` is
the robot of column b), so that one pass over the in-neighbour lists serves all
columns at once. B_k is applied in :func:`_row` (and, to a single column, in :func:`_entry`:
the same arithmetic in the same order, on a scalar; tested bit for bit); each sweep
(:func:`advance_columns` for the rules' sums, :func:`advance_crossing` for eq. 46's
crossing times, :func:`advance_sums` for κ, λ) accumulates what its analysis needs as it
goes. B_k ≥ 0 elementwise when β (d_i + δ_ik) ≤ 1 for every i; the callers check it."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from ...core.graph import Graph

#: entries below this are set to 0 in the recursions: the wavefront of a column
#: otherwise passes through subnormal numbers, 10-100x slower. The error is at most
#: TINY per entry and period, so at most t·TINY on c and t²·TINY on S after t
#: periods (‖A‖_∞ ≤ 1): the callers add it to their rounding slack.
TINY = 1e-250


@dataclass(frozen=True)
class Adjacency:
    """In- and out-neighbour lists of a graph, for the compiled recursions.

    ``src[first[i]:first[i + 1]]`` are robot i's in-neighbours (Lv)_i = d_i v_i − Σ v_j;
    ``dst[out_first[j]:out_first[j + 1]]`` the robots j sends to (for Lᵀ);
    ``deg`` the in-degrees d_i (float).
    """

    n: int
    src: np.ndarray
    first: np.ndarray
    dst: np.ndarray
    out_first: np.ndarray
    deg: np.ndarray

    @classmethod
    def of(cls, graph: Graph) -> Adjacency:
        """The lists of ``graph``."""
        e = np.array(graph.edges, dtype=np.int64).reshape(-1, 2)
        by_to = np.lexsort((e[:, 0], e[:, 1]))
        by_from = np.lexsort((e[:, 1], e[:, 0]))
        first = np.searchsorted(e[by_to, 1], np.arange(graph.n + 1)).astype(np.int64)
        out_first = np.searchsorted(e[by_from, 0], np.arange(graph.n + 1)).astype(np.int64)
        deg = np.bincount(e[:, 1], minlength=graph.n).astype(float)
        return cls(graph.n, e[by_to, 0].copy(), first, e[by_from, 1].copy(), out_first, deg)


def ratios(new: np.ndarray, old: np.ndarray) -> np.ndarray:
    """new / old entrywise (0/0 = 0, x/0 = inf): the factors of a certificate new ≤ s old."""
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(old > 0, new / old, np.where(new > 0, np.inf, 0.0))


def ratio_max(new: np.ndarray, old: np.ndarray) -> np.ndarray:
    """Per column, the smallest s with new ≤ s old componentwise (see :func:`ratios`)."""
    return ratios(new, old).max(axis=0)


def column_of_row(rows: np.ndarray, n: int) -> np.ndarray:
    """(N,) the column whose monitored robot is row i, or −1."""
    out = np.full(n, -1, dtype=np.int64)
    out[rows] = np.arange(len(rows))
    return out


@njit(inline="always")
def _row(i, v, o, src, first, deg, col_of_row, beta):  # pragma: no cover - compiled
    """o = row i of B_k v for every column b (k the robot of column b): the one place the
    observer matrix B_k = I − β(L + e_k e_kᵀ) is applied."""
    a = 1.0 - beta * deg[i]
    vi = v[i]
    for b in range(o.shape[0]):
        o[b] = a * vi[b]
    for e in range(first[i], first[i + 1]):
        vj = v[src[e]]
        for b in range(o.shape[0]):
            o[b] += beta * vj[b]
    cb = col_of_row[i]
    if cb >= 0:
        o[cb] -= beta * vi[cb]


@njit(inline="always")
def _entry(i, v, src, first, deg, col_of_row, beta):  # pragma: no cover - compiled
    """Entry i of B_k v for one column v (N,): :func:`_row`'s arithmetic in its order, on a
    scalar (a row of one column walked through :func:`_row`'s inner loops cost 3.5× as
    much), flushed as :func:`_flush` does."""
    vi = v[i]
    o = (1.0 - beta * deg[i]) * vi
    for e in range(first[i], first[i + 1]):
        o += beta * v[src[e]]
    if col_of_row[i] >= 0:
        o -= beta * vi
    return o if abs(o) > TINY else 0.0


@njit(inline="always")
def _flush(o):  # pragma: no cover - compiled
    """Entries below :data:`TINY` to zero: no subnormal arithmetic (see TINY)."""
    for b in range(o.shape[0]):
        o[b] = o[b] if abs(o[b]) > TINY else 0.0


@njit(inline="always")
def _watch(o, vi, worst, low):  # pragma: no cover - compiled
    """Track, over the rows of the last period, max(c(t + 1) − c(t)) and min c(t)."""
    for b in range(o.shape[0]):
        worst[b] = max(worst[b], o[b] - vi[b])
        low[b] = min(low[b], vi[b])


@njit(inline="always")
def _certify(worst, low, steps, t0, cert):  # pragma: no cover - compiled
    """Set ``cert[b]`` = t0 + steps − 1 where the last period was non-increasing and
    positive in column b (see :func:`advance_columns`)."""
    for b in range(worst.shape[0]):
        if steps > 0 and worst[b] <= 0.0 and low[b] > 0.0 and cert[b] < 0:
            cert[b] = t0 + steps - 1


@njit(cache=True)
def apply(v, out, src, first, deg, col_of_row, beta):  # pragma: no cover - compiled
    """out[:, b] = B_k v[:, b] with B_k = I − β(L + e_k e_kᵀ), k the robot of column b.

    With the out-neighbour lists (:meth:`Adjacency.transposed`) it applies B_kᵀ.
    """
    for i in range(v.shape[0]):
        _row(i, v, out[i], src, first, deg, col_of_row, beta)


@njit(cache=True)
def advance_columns(
    v,
    prev,
    tot,
    tv,
    imax,
    alpha,
    gamma,
    structured,
    src,
    first,
    deg,
    col_of_row,
    beta,
    steps,
    t0,
    cert,
):  # pragma: no cover - compiled
    """``steps`` periods of c ← B_k c for every column, accumulating as it goes.

    On entry ``v`` holds c(t0) = B^{t0} e_k (column k), ``tot`` = S(t0) = Σ_{m<t0} c_m
    and ``tv`` = TV(t0) = Σ_{1≤m≤t0} |c_m − c_{m−1}|. On return the newest column
    c(t0 + steps) is in ``v`` if ``steps`` is even, else in ``prev`` (the other buffer
    then holds c(t0 + steps − 1)); entries below :data:`TINY` are flushed to 0. With
    ``structured``, ``imax`` takes the largest
    alpha_b |c_t − d_t| + gamma |d_t|, d_t = (c_t − c_{t+1}) / β, over the periods
    stepped from. ``cert[b]`` (−1 until then) is set to t0 + steps − 1 if at that last
    period c(t + 1) ≤ c(t) with c(t) > 0 componentwise: from then on every entry of
    column b is non-increasing, since B ≥ 0.
    """  # fmt: skip
    n, kk = v.shape
    inv = 1.0 / beta
    worst = np.full(kk, -np.inf)
    low = np.full(kk, np.inf)
    cur, nxt = v, prev
    for s in range(steps):
        for i in range(n):
            o, vi = nxt[i], cur[i]
            _row(i, cur, o, src, first, deg, col_of_row, beta)
            _flush(o)
            ti, si = tv[i], tot[i]
            for b in range(kk):
                ti[b] += abs(o[b] - vi[b])
                si[b] += vi[b]
            if structured:
                mi = imax[i]
                for b in range(kk):
                    d = (vi[b] - o[b]) * inv
                    mi[b] = max(mi[b], alpha[b] * abs(vi[b] - d) + gamma * abs(d))
            if s == steps - 1:
                _watch(o, vi, worst, low)
        cur, nxt = nxt, cur
    _certify(worst, low, steps, t0, cert)


@njit(cache=True)
def advance_crossing(
    v, prev, tot, lagged, r, need, when, src, first, deg, col_of_row, beta, steps, t0, cert
):  # pragma: no cover - compiled
    """``steps`` periods of c ← B_k c accumulating S = Σ_{m<t} c_m (``tot``); ``when[i, b]``
    (−1 until then) records the first t with S_ib(t) ≥ ``need[i, b]``. Buffers and
    ``cert`` as in :func:`advance_columns`. With ``lagged`` (a drive's lag, factor ``r`` =
    e^(−h/τ) a period) the sum compared is W = S − E, E(t) = Σ_{m<t} r^(t−1−m) c_m (kept in
    ``lagged``): the signature of a drift that grows as 1 − r^m
    (:func:`.delays.predicted_delays`)."""
    n, kk = v.shape
    worst = np.full(kk, -np.inf)
    low = np.full(kk, np.inf)
    cur, nxt = v, prev
    lag = lagged.shape[0] > 0
    for s in range(steps):
        t1 = t0 + s + 1
        for i in range(n):
            o, vi = nxt[i], cur[i]
            _row(i, cur, o, src, first, deg, col_of_row, beta)
            _flush(o)
            si, ni, wi = tot[i], need[i], when[i]
            if lag:
                ei = lagged[i]
                for b in range(kk):
                    si[b] += vi[b]
                    ei[b] = r * ei[b] + vi[b]
                    hit = (wi[b] < 0) & (si[b] - ei[b] >= ni[b])
                    wi[b] = t1 if hit else wi[b]
            else:
                for b in range(kk):
                    si[b] += vi[b]
                    hit = (wi[b] < 0) & (si[b] >= ni[b])
                    wi[b] = t1 if hit else wi[b]
            if s == steps - 1:
                _watch(o, vi, worst, low)
        cur, nxt = nxt, cur
    _certify(worst, low, steps, t0, cert)


@njit(cache=True)
def _step_rows(cur, nxt, src, first, deg, col_of_row, beta):  # pragma: no cover - compiled
    """nxt = B_k cur column by column (as :func:`apply`), flushing entries below TINY."""
    for i in range(cur.shape[0]):
        _row(i, cur, nxt[i], src, first, deg, col_of_row, beta)
        _flush(nxt[i])


@njit(cache=True)
def advance_sums(
    a, a2, u, u2, src, first, dst, out_first, deg, col_of_row, beta, steps, amax, umax
):  # pragma: no cover - compiled
    """``steps`` periods of the row sums a ← B_k a and column sums u ← B_kᵀ u (N, K),
    recording ‖B_k^n‖_∞ = max_i a_i and ‖B_k^n‖₁ = max_i u_i of every new n in
    ``amax[s]``, ``umax[s]`` (steps, K). The newest sums are in ``a``, ``u`` if ``steps``
    is even, else in ``a2``, ``u2``; entries below :data:`TINY` are flushed to 0."""
    n, kk = a.shape
    if kk == 1:  # one column (a graph invariant under rotation): entry by entry
        _advance_sums_one(
            a.reshape(n), a2.reshape(n), u.reshape(n), u2.reshape(n), src, first, dst,
            out_first, deg, col_of_row, beta, steps, amax[:, 0], umax[:, 0],
        )  # fmt: skip
        return
    ca, na, cu, nu = a, a2, u, u2
    for s in range(steps):
        _step_rows(ca, na, src, first, deg, col_of_row, beta)
        _step_rows(cu, nu, dst, out_first, deg, col_of_row, beta)
        ma, mu = amax[s], umax[s]
        ma[:] = 0.0  # row by row, in memory order; each column's maximum over i in order
        mu[:] = 0.0
        for i in range(n):
            nai, nui = na[i], nu[i]
            for b in range(kk):
                ma[b] = max(ma[b], nai[b])
                mu[b] = max(mu[b], nui[b])
        ca, na = na, ca
        cu, nu = nu, cu


@njit(cache=True)
def _advance_sums_one(
    a, a2, u, u2, src, first, dst, out_first, deg, col_of_row, beta, steps, amax, umax
):  # pragma: no cover - compiled
    """:func:`advance_sums` for one column, the sums (N,) and their maxima (steps,): the same
    numbers, each entry's maximum taken as it is made."""
    n = a.shape[0]
    ca, na, cu, nu = a, a2, u, u2
    for s in range(steps):
        x = y = 0.0
        for i in range(n):
            na[i] = o = _entry(i, ca, src, first, deg, col_of_row, beta)
            x = max(x, o)
        for i in range(n):
            nu[i] = o = _entry(i, cu, dst, out_first, deg, col_of_row, beta)
            y = max(y, o)
        amax[s], umax[s] = x, y
        ca, na = na, ca
        cu, nu = nu, cu


@njit(inline="always")
def _ratio_bracket(new, old, b):  # pragma: no cover - compiled
    """max_i and min_i of :func:`ratios` (new, old) in column b: its Collatz-Wielandt bracket."""
    hi, lo = -np.inf, np.inf
    for i in range(new.shape[0]):
        o, v = old[i, b], new[i, b]
        r = v / o if o > 0 else (np.inf if v > 0 else 0.0)
        hi = max(hi, r)
        lo = min(lo, r)
    return hi, lo


@njit(cache=True, nogil=True)
def sweep_sums(
    a, a2, u, u2, src, first, dst, out_first, deg, col_of_row, beta, chunk, settle, done,
    max_steps, work, max_work, amax, umax, s_a, s_u, settled,
):  # fmt: skip  # pragma: no cover - compiled
    """Chunks of ``chunk`` (even) steps of :func:`advance_sums` from step ``done``, their
    maxima into the rows of ``amax``, ``umax`` (rows, K), until a column is settled (as
    :func:`.decay._decay_bounds_fast` defines it) or the next chunk would not fit.

    After each chunk the bracket of each column's decay rate (:func:`_ratio_bracket` of the
    newest sums over the previous ones) gives ``s_a``, ``s_u`` (K,) and ``settled`` (K,):
    within ``settle``, or any certificate (s_a, s_u < 1) once ``work`` entry updates exceed
    ``max_work``, or every column at ``max_steps``. Returns (steps done, work, rows written).
    Compiled and without the GIL, so κ, λ can be computed on a helper thread."""
    n, kk = a.shape
    edges = src.shape[0]
    rows = 0
    while rows + chunk <= amax.shape[0]:
        advance_sums(
            a, a2, u, u2, src, first, dst, out_first, deg, col_of_row, beta, chunk,
            amax[rows : rows + chunk], umax[rows : rows + chunk],
        )  # fmt: skip
        rows += chunk
        done += chunk
        any_settled = False
        work += 2 * chunk * kk * (n + edges)
        for b in range(kk):  # chunk is even: the newest sums in a, u, the previous in a2, u2
            ha, la = _ratio_bracket(a, a2, b)
            hu, lu = _ratio_bracket(u, u2, b)
            s_a[b], s_u[b] = ha, hu
            certified = (ha < 1.0) & (hu < 1.0)
            ok = (
                (1.0 - ha >= (1.0 - settle) * (1.0 - la))
                & (1.0 - hu >= (1.0 - settle) * (1.0 - lu))
                & certified
            )
            if work > max_work:  # past the budget any certificate is valid, only looser
                ok |= certified
            if done >= max_steps:
                ok = True
            settled[b] = ok
            any_settled |= ok
        if any_settled:
            break
    return done, work, rows


@njit(cache=True)
def best_rate(log_a, log_u, q, lam_cert, fractions):  # pragma: no cover - compiled
    """κ, λ minimising κ/λ over λ = ``lam_cert`` × ``fractions``, with
    κ(λ) = √(max_n ‖B^n‖_∞ σ^{−n} · max_n ‖B^n‖₁ σ^{−n}), σ = 1 − λ/q (logs given)."""
    best, kap, lam = np.inf, np.inf, 0.0
    for f in fractions:
        lm = lam_cert * f
        if lm <= 0.0:
            continue
        theta = -math.log1p(-lm / q)
        ma = -np.inf
        mu = -np.inf
        for m in range(len(log_a)):
            ma = max(ma, log_a[m] + m * theta)
            mu = max(mu, log_u[m] + m * theta)
        k = math.exp(0.5 * (ma + mu))
        if k / lm < best:
            best, kap, lam = k / lm, k, lm
    return kap, lam
