"""Rule ``"block_row"`` (eq. B of ``docs/thresholds.md``).

ⁱμ_k(t) = ‖e_iᵀ P_k A_k^t‖ y0_k + h(k_o η̄ + √N ξ̄) Σ_{j<t} ‖e_iᵀ P_k A_k^j‖ + δ_ik η̄
+ ē(δ_ik + O_ik(t)). It needs the rows of P_k A_k^j, N² numbers per monitored robot and
period (:func:`advance_rows`, :func:`row_envelope`): it is exact and limited to teams of at
most :data:`BLOCK_ROW_MAX` robots."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ...core.graph import Graph, reaches_all, rotation_invariant
from ...errors import ScenarioError
from .envelope import (
    CHECK,
    Envelope,
    Start,
    _Enveloped,
    _expand,
    _extend_breakpoints,
    _next_breakpoint,
    _unbounded,
    check_nonnegative,
    column_envelope,
)
from .kernels import Adjacency, apply, column_of_row, ratio_max

#: block_row tabulates N² row norms per monitored robot and period (~N³ per period)
BLOCK_ROW_MAX = 64


class BlockRow(_Enveloped):
    """The block-row rule (``[onboard] thresholds = "block_row"``), teams of at most
    :data:`BLOCK_ROW_MAX` robots.

    A bound when each robot's measurement noise is within η̄ and the drift of
    y_k = x_k − ∫u_k is a slow part (within h ξ̄ per period) plus an offset within
    ``drift_bound`` = ē: ⁱμ_k(t) = ‖e_iᵀP_kA_k^t‖ y0_k + h(k_o η̄ + √N ξ̄) Σ_{j<t}
    ‖e_iᵀP_kA_k^j‖ + δ_ik η̄ + ē(δ_ik + O_ik(t)) (``docs/thresholds.md``, eq. B), y0_k
    bounding ‖ỹ*_k‖ (all observers); after an exclusion it restarts from
    ‖ỹ*_k(t)‖ ≤ ‖A_k^t‖₂ y0_k + h(k_o η̄ + √N ξ̄) Σ_{m<t} ‖A_k^m‖₂ + 2ē√N. Needs
    k_o h (d_max + 1) ≤ 1.
    """

    def _structured(self, n: int, y0: float) -> Start:
        return Start(np.full(n, y0))

    def restart(self, graph: Graph, y0: np.ndarray, t0: float) -> None:
        """Start anew at ``t0`` on ``graph`` with ‖ỹ*_k(t0)‖ ≤ ``y0[k]``."""
        self._begin(graph, Start(np.asarray(y0, float)), t0)

    def drop(self, p: int, graph: Graph, t: float) -> None:
        """Restart on the reduced graph from the bound of ‖ỹ*_k(t)‖ (the bracket)."""
        keep = np.delete(np.arange(self.graph.n), p)
        self.restart(graph, self.bracket(t)[keep], t)

    def bracket(self, t: float) -> np.ndarray:
        """A bound of ‖ỹ*_k(t)‖ per monitored robot k (see the class)."""
        return self.env_bracket[self.env.index(self._period(t))].copy()

    def _envelope(self, graph: Graph, start: Start) -> Envelope:
        env, self.env_bracket = row_envelope(
            graph, self.ko, self.h, start.alpha, self.eta_bar, self.xi_bar, self.drift
        )
        return env


@njit(cache=True)
def advance_rows(
    x,
    g,
    gp,
    u,
    up,
    rowsum,
    rowmax,
    normsum,
    normmax,
    src,
    first,
    dst,
    out_first,
    deg,
    col_of_row,
    rows,
    beta,
    steps,
):  # pragma: no cover - compiled
    """``steps`` periods of X_b = P_k A_k^t for every monitored k = ``rows[b]`` (x (K, N, N)).

    Before each step adds ‖e_iᵀ X‖ to ``rowsum`` (N, K) and maximises it into
    ``rowmax``; with the row sums g = A^t 1 and column sums u = (Aᵀ)^t 1 (N, K),
    ‖A^t‖₂ ≤ √(‖A^t‖₁ ‖A^t‖_∞) = √(max u · max g) is added to ``normsum`` and
    maximised into ``normmax`` (K,). X ← X − β X P_k with
    (X P_k)_{il} = X_il (d_l + δ_lk) − Σ_{j: l→j} X_ij. The newest g, u are in the
    first buffers if ``steps`` is even, else in the second ones.
    """  # fmt: skip
    kk, n, _ = x.shape
    tmp = np.empty(n)
    for _ in range(steps):
        for b in range(kk):
            an = 0.0
            a1 = 0.0
            for i in range(n):
                an = max(an, g[i, b])
                a1 = max(a1, u[i, b])
            nb = math.sqrt(an * a1)
            normsum[b] += nb
            normmax[b] = max(normmax[b], nb)
            k = rows[b]
            xb = x[b]
            for i in range(n):
                xi = xb[i]
                acc = 0.0
                for col in range(n):
                    acc += xi[col] * xi[col]
                r = math.sqrt(acc)
                rowsum[i, b] += r
                rowmax[i, b] = max(rowmax[i, b], r)
                for col in range(n):
                    p = xi[col] * (deg[col] + (1.0 if col == k else 0.0))
                    for e in range(out_first[col], out_first[col + 1]):
                        p -= xi[dst[e]]
                    tmp[col] = p
                for col in range(n):
                    xi[col] -= beta * tmp[col]
        apply(g, gp, src, first, deg, col_of_row, beta)
        apply(u, up, dst, out_first, deg, col_of_row, beta)
        g, gp = gp, g
        u, up = up, u


class _RowSweep:
    """The rows of P_k A_k^t for the monitored robots ``ks``, as an envelope of
    y0_k ‖e_iᵀ P_k A_k^t‖ + ``noise`` Σ_{m<t} ‖e_iᵀ P_k A_k^m‖ (eq. B without its δη̄ and
    ē terms) and of the bracket y0_k ‖A_k^t‖₂ + ``noise`` Σ_{m<t} ‖A_k^m‖₂.

    A robot k stops at T once its column sums u and row sums g contract
    (Aᵀu ≤ s_u u, A g ≤ s_g g, s < 1) and the bound Σ_{m<T} row + tail no longer
    improves by 0.1 % per look. Tails: |e_iᵀ P A^{T+m}| ≤ |e_iᵀ P A^T| A^m ≤ C_i s_u^m uᵀ
    (C_i = max_l |[P A^T]_il| / u_l), so row_i(T + m) ≤ C_i ‖u‖₂ s_u^m; and
    ‖A^{T+m}‖₂ ≤ √(max u · max g) (s_u s_g)^{m/2}.
    """

    def __init__(
        self, graph: Graph, beta: float, ks: np.ndarray, y0: np.ndarray, noise: float,
        max_periods: int,
    ) -> None:  # fmt: skip
        adj = Adjacency.of(graph)
        n, kk = graph.n, len(ks)
        self.adj, self.beta, self.ks, self.y0, self.noise, self.n = adj, beta, ks, y0, noise, n
        self.max_periods = max_periods
        self.x = np.repeat(graph.laplacian()[None], kk, axis=0)
        self.x[np.arange(kk), ks, ks] += 1.0  # X(0) = P_k
        self.g, self.gp = np.ones((n, kk)), np.empty((n, kk))
        self.u, self.up = np.ones((n, kk)), np.empty((n, kk))
        self.rowsum, self.rowmax = np.zeros((n, kk)), np.zeros((n, kk))
        self.normsum, self.normmax = np.zeros(kk), np.zeros(kk)
        self.best = np.full((n, kk), np.inf)
        self.cols = np.arange(kk)
        self.t = 0
        self.bp = [0, 1]
        self.tables: list[np.ndarray] = []
        self.brackets: list[np.ndarray] = []
        self.T = np.zeros(kk, dtype=np.int64)
        self.q_ret = np.zeros(kk, dtype=np.int64)
        self.opened = np.zeros(kk, bool)
        self.s_u, self.rho = np.ones(kk), np.ones(kk)
        self.tmax, self.sum_inf, self.rowmax_bin = (np.zeros((n, kk)) for _ in range(3))
        self.a_t, self.nsum_inf, self.nmax_bin = np.zeros(kk), np.zeros(kk), np.zeros(kk)

    def run(self) -> Envelope:
        q = 0
        while True:
            t = self.t
            if t == self.bp[q] and len(self.tables) == q:
                self.tables.append(np.full((self.n, len(self.ks)), np.nan))
                self.brackets.append(np.full(len(self.ks), np.nan))
                self.rowmax[:] = 0.0
                self.normmax[:] = 0.0
            if t == self.bp[q + 1] - 1:
                self._close(q)
                q += 1
                self.bp.append(_next_breakpoint(self.bp[-1]))
            if t % CHECK == 0 or t >= self.max_periods:
                self._retire(q)
            if not len(self.cols):
                break
            target = self.bp[q] if t < self.bp[q] else self.bp[q + 1] - 1
            self._advance(min(target, t + CHECK - t % CHECK) - t)
        return self._finish()

    def _col_of_row(self) -> np.ndarray:
        return column_of_row(self.ks[self.cols], self.n)

    def _advance(self, steps: int) -> None:
        a = self.adj
        advance_rows(
            self.x, self.g, self.gp, self.u, self.up, self.rowsum, self.rowmax, self.normsum,
            self.normmax, a.src, a.first, a.dst, a.out_first, a.deg, self._col_of_row(),
            self.ks[self.cols], self.beta, steps,
        )  # fmt: skip
        if steps % 2:
            self.g, self.gp = self.gp, self.g
            self.u, self.up = self.up, self.u
        self.t += steps

    def _norm_now(self) -> np.ndarray:
        return np.sqrt(self.g.max(axis=0) * self.u.max(axis=0))

    def _close(self, q: int) -> None:
        """At the last period of interval q: the largest row over it, the sums up to it."""
        rows = np.linalg.norm(self.x, axis=2).T
        np.maximum(self.rowmax, rows, out=self.rowmax)
        np.maximum(self.normmax, self._norm_now(), out=self.normmax)
        y0 = self.y0[self.cols]
        self.tables[q][:, self.cols] = y0 * self.rowmax + self.noise * self.rowsum
        self.brackets[q][self.cols] = y0 * self.normmax + self.noise * self.normsum

    def _retire(self, q: int) -> None:
        a, cor = self.adj, self._col_of_row()
        gn, un = np.empty_like(self.g), np.empty_like(self.u)
        apply(self.g, gn, a.src, a.first, a.deg, cor, self.beta)
        apply(self.u, un, a.dst, a.out_first, a.deg, cor, self.beta)
        s_u, s_g = ratio_max(un, self.u), ratio_max(gn, self.g)
        with np.errstate(divide="ignore", invalid="ignore"):
            ax = np.abs(self.x)
            ut = self.u.T[:, None, :]
            coef = np.where(ut > 0, ax / ut, np.where(ax > 0, np.inf, 0.0)).max(axis=2).T
            tmax = coef * np.linalg.norm(self.u, axis=0)
            tsum = np.where(s_u < 1.0, tmax / (1.0 - s_u), np.inf)
        bound = self.rowsum + tsum
        settled = (bound >= (1.0 - 1e-3) * self.best).all(axis=0) & (s_u < 1.0) & (s_g < 1.0)
        np.minimum(self.best, bound, out=self.best)
        done = settled if self.t < self.max_periods else np.ones(len(self.cols), bool)
        if not done.any():
            return
        idx = np.flatnonzero(done)
        c = self.cols[idx]
        self.T[c], self.q_ret[c] = self.t, q
        self.opened[c] = len(self.tables) == q + 1
        self.s_u[c] = np.minimum(s_u[idx], 1.0)
        self.rho[c] = np.sqrt(np.minimum(s_u[idx], 1.0) * np.minimum(s_g[idx], 1.0))
        self.tmax[:, c], self.sum_inf[:, c] = tmax[:, idx], bound[:, idx]
        self.rowmax_bin[:, c] = self.rowmax[:, idx]
        a_t = self._norm_now()[idx]
        rho = self.rho[c]
        with np.errstate(divide="ignore"):
            self.nsum_inf[c] = self.normsum[idx] + np.where(rho < 1.0, a_t / (1.0 - rho), np.inf)
        self.a_t[c], self.nmax_bin[c] = a_t, self.normmax[idx]
        keep = ~done
        self.x = self.x[keep]
        for name in ("g", "gp", "u", "up", "rowsum", "rowmax", "best"):
            setattr(self, name, np.ascontiguousarray(getattr(self, name)[:, keep]))
        self.normsum, self.normmax = self.normsum[keep], self.normmax[keep]
        self.cols = self.cols[keep]

    def _finish(self) -> Envelope:
        y0, T, noise = self.y0, self.T, self.noise
        init_max = y0 * self.tmax.max(axis=0)
        target = np.maximum(1e-4 * noise * self.sum_inf.min(axis=0), 1e-15)
        bp = _extend_breakpoints(self.bp, T, init_max, target, self.s_u)
        n, kk = self.n, len(self.ks)
        while len(self.tables) < len(bp):
            self.tables.append(np.full((n, kk), np.nan))
            self.brackets.append(np.full(kk, np.nan))
        for q in range(len(bp)):
            here = (self.q_ret == q) & self.opened
            if here.any():
                top = np.maximum(self.rowmax_bin[:, here], self.tmax[:, here])
                self.tables[q][:, here] = y0[here] * top + noise * self.sum_inf[:, here]
                nmax = np.maximum(self.nmax_bin[here], self.a_t[here])
                self.brackets[q][here] = y0[here] * nmax + noise * self.nsum_inf[here]
            after = bp[q] > T
            if after.any():
                m = bp[q] - T[after]
                self.tables[q][:, after] = (
                    y0[after] * self.tmax[:, after] * self.s_u[after] ** m
                    + noise * self.sum_inf[:, after]
                )
                self.brackets[q][after] = (
                    y0[after] * self.a_t[after] * self.rho[after] ** m
                    + noise * self.nsum_inf[after]
                )
        for table in self.tables:
            table[:, ~np.isfinite(y0)] = np.inf
            assert not np.isnan(table).any()
        self.bracket = np.array(self.brackets)
        return Envelope(bp, self.tables, T.copy(), np.ones(kk, bool))


def row_envelope(
    graph: Graph,
    ko: float,
    h: float,
    y0: np.ndarray,
    eta_bar: float,
    xi_bar: float,
    drift: float,
    max_periods: int = 200_000,
) -> tuple[Envelope, np.ndarray]:
    """The envelope of eq. B for every monitored robot k of ``graph`` (exact rows,
    :class:`_RowSweep`), plus δ_ik η̄ and ē(δ_ik + O_ik(t)) from the column sweep; and
    per interval the bound ‖ỹ*_k(t)‖ ≤ ‖A^t‖₂ y0_k + h(k_o η̄ + √N ξ̄) Σ_{m<t} ‖A^m‖₂ + 2ē√N
    (B, N) a restart starts from."""
    n = graph.n
    if n > BLOCK_ROW_MAX:
        raise ScenarioError(
            'onboard.thresholds: "block_row" tabulates N × N row norms per robot and period '
            f"(about N³ operations per period) and is limited to teams of at most "
            f'{BLOCK_ROW_MAX} robots, got {n}; use thresholds = "l1" (or "drive"), which scale'
        )
    check_nonnegative(graph, ko, h, "block_row")
    noise = h * (ko * eta_bar + math.sqrt(n) * xi_bar)
    finite = reaches_all(graph)
    ks = np.flatnonzero(finite)
    if len(ks) == 0:
        return _unbounded(n), np.full((1, n), np.inf)
    y0 = np.asarray(y0, float)
    circulant = bool(finite.all()) and rotation_invariant(graph) and bool(np.all(y0 == y0[0]))
    if circulant:
        ks = ks[:1]
    sweep = _RowSweep(graph, h * ko, ks, y0[ks], noise, max_periods)
    rows = _expand(sweep.run(), n, ks, circulant)
    bracket_k = np.full((len(sweep.bracket), n), np.inf)
    bracket_k[:, ks] = sweep.bracket
    if circulant:
        bracket_k[:] = sweep.bracket[:, :1]
    parts = [rows]
    if drift > 0.0:
        start = Start(np.zeros(n))
        parts.append(column_envelope(graph, ko, h, start, (0.0, drift, 0.0), "block_row"))
    bp = max((p.bp for p in parts), key=len)
    eye = eta_bar * np.eye(n)
    tables = []
    for q in range(len(bp)):  # the grids share their breakpoints; a shorter one's last
        tab = eye.copy()  # interval covers the longer one's remaining ones
        for p in parts:
            tab += p.table[min(q, len(p.bp) - 1)]
        tables.append(tab)
    bracket = bracket_k[np.minimum(np.arange(len(bp)), len(rows.bp) - 1)]
    return Envelope(bp, tables, rows.steps, rows.certified), bracket + 2.0 * drift * math.sqrt(n)
