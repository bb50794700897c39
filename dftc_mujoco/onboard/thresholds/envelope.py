"""What the rules derived for the discrete-time observer share (``docs/thresholds.md``).

With P_k = L + e_k e_kᵀ, β = h k_o, A_k = I − β P_k, c_t = [A_k^t]_{ik} (≥ 0 when
β (d_max + 1) ≤ 1, :func:`check_nonnegative`), d_t = (c_t − c_{t+1})/β,
TV(t) = Σ_{1≤m≤t} |c_m − c_{m−1}|, O(t) = TV(t − 1) + c_{t−1} and S(t) = Σ_{m<t} c_m → 1/β.
The thresholds are stored as an :class:`Envelope` on a geometric grid of periods (a bound
for every period of each interval), not per period. :func:`column_envelope` sweeps the
columns A_k^j e_k (one sparse recursion per monitored robot, batched and compiled in
:mod:`.kernels`), stopped once every entry of a column is certified non-increasing (exact
tails from there on) or at a work budget (rigorous looser tails). :class:`_Enveloped` is
the block the rules l1, drive and block_row share: its start from the structured first
estimates, and its restart after an exclusion from the residuals' bound
(:func:`grounded_solve`, the rows of P_k⁻¹)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ...core.graph import Graph, reaches_all, rotation_invariant
from ...errors import ScenarioError
from ..block import TeamConfig
from .compensation import compensation_offset, estimator_gain
from .kernels import TINY, Adjacency, advance_columns, apply, column_of_row
from .paper import Thresholds

#: single-period bins up to this period, then each bin RATIO times longer
FIRST_BINS = 8


RATIO = 1.25


#: a sweep stops after this many periods even if a column is not certified (then a
#: looser, still rigorous tail bound is used), or after MAX_WORK column-entry updates:
#: its cost is bounded whatever the graph's mixing time (about a second at N = 1000)
MAX_PERIODS = 1_000_000


MAX_WORK = 5e8


SETTLED = 0.9  # a column stops once min_i/max_i of c_i/R_i (its decay rate) is above this


CHECK = 32  # periods between two looks at the certificates (even: see _crossing_periods)


_EPS = 2.3e-16


#: added to every threshold of l1 and drive: the residual itself is computed in floating
#: point (differences of estimates of a few metres, rounded to ~1e-15 m), and the
#: structured start proves some thresholds exactly 0 at first
FLOOR = 1e-9


def _next_breakpoint(last: int) -> int:
    return last + 1 if last < FIRST_BINS else math.ceil(last * RATIO)


def _extend_breakpoints(
    bp: list[int], T: np.ndarray, init_max: np.ndarray, target: np.ndarray, rate: np.ndarray
) -> np.ndarray:
    """Extend the breakpoints ``bp`` (in place) past the periods ``T`` by as many as the
    initial part, decaying at ``rate`` per period from ``init_max``, needs to fall below
    ``target``, and return them as an array."""
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        more = np.where(
            (rate < 1.0) & (init_max > target) & np.isfinite(init_max),
            np.ceil(np.log(target / init_max) / np.log(rate)),
            0.0,
        )
    horizon = min(float((T + more).max()), float(T.max()) + 1e8)
    while bp[-1] < horizon:
        bp.append(_next_breakpoint(bp[-1]))
    return np.array(bp, dtype=np.int64)


def _slack(t: int, mass: float) -> float:
    """A bound of the rounding error of R = mass − S after t additions (and of the
    flushed subnormals, :data:`~.columns.TINY`)."""
    return (t + 2) * _EPS * mass + (t + 1) ** 2 * TINY


@dataclass
class Envelope:
    """Thresholds on a coarse grid of periods after a (re)start.

    ``table[q]`` (N, N) bounds ⁱμ_k for every period j with ``bp[q] <= j < bp[q + 1]``;
    the last one for every j ≥ ``bp[-1]`` (the steady value). ``steps[k]`` is how many
    periods were swept for robot k and ``certified[k]`` whether its tail is exact
    (every entry monotone) or the looser mass bound (a sweep cut short).
    """

    bp: np.ndarray
    table: list[np.ndarray]
    steps: np.ndarray
    certified: np.ndarray

    def index(self, j: int) -> int:
        """The interval that contains period ``j`` (≥ 0)."""
        return int(np.searchsorted(self.bp, j, side="right")) - 1

    @property
    def steady(self) -> np.ndarray:
        """ⁱμ_k for every period after the last breakpoint."""
        return self.table[-1]


def check_nonnegative(graph: Graph, ko: float, h: float, rule: str) -> None:
    """Refuse a rule that needs A_k ≥ 0 elementwise, i.e. h k_o (d_i + δ_ik) ≤ 1."""
    dmax = float(graph.in_degree().max()) if graph.n else 0.0
    if h * ko * (dmax + 1.0) > 1.0 + 1e-12:
        raise ScenarioError(
            f'onboard.thresholds: "{rule}" needs the observer matrix A_k = I − h k_o(L + e_k e_kᵀ) '
            f"to be non-negative, i.e. ko * h * (max in-degree + 1) <= 1 (h: the observers' "
            f"step, the control period or a round of the network); got "
            f"{ko:g} * {h:g} * {dmax + 1:g} = {h * ko * (dmax + 1):g}. Lower gains.ko or "
            'physics.control_period, or use thresholds = "paper"'
        )


@dataclass(frozen=True)
class Start:
    """How the initial-error term of eqs. L1 and D is bounded after a (re)start.

    ``structured`` (the start of a run): every robot begins with ⁱŷ_k(0) = the planned
    slot of k (i ≠ k) and ᵏŷ_k(0) = its own measurement, so the initial term of
    ⁱr_k(t) is −[(c_t − d_t) aᵀ + d_t bᵀ] with d_t = (c_t − c_{t+1}) / (h k_o) and
    ‖a‖ ≤ ``alpha[k]``, ‖b‖ ≤ ``gamma``. Otherwise (a restart) it is e_iᵀ A_k^t Z with
    max_l ‖z_l‖ ≤ ``alpha[k]``, at most ``alpha[k]`` h k_o R_ik(t) (A ≥ 0).
    """

    alpha: np.ndarray
    gamma: float = 0.0
    structured: bool = False


class _ColumnSweep:
    """The recursion c ← A_k c for the monitored robots ``ks``, turned into an envelope.

    On every interval [a, b) of periods: the initial term (:class:`Start`) at its
    largest (structured: tracked period by period; restart: at a, since R decreases)
    plus a_tv (δ + TV) + a_off (δ + O) + a_slow S at b − 1 (they increase).
    """

    def __init__(
        self,
        graph: Graph,
        beta: float,
        ks: np.ndarray,
        start: Start,
        mu_coef: tuple[float, float, float],
        max_work: float,
    ) -> None:
        adj = Adjacency.of(graph)
        n, kk = adj.n, len(ks)
        self.graph, self.adj, self.beta, self.ks, self.n = graph, adj, beta, ks, n
        self.mass = 1.0 / beta
        self.start = start
        self.alpha = np.asarray(start.alpha, float)
        # the tail below uses α h k_o R for a restart, α |c − d| + γ |d| for the start
        self.tail_alpha = self.alpha if start.structured else self.alpha * beta
        self.a_tv, self.a_off, self.a_slow = mu_coef
        self.max_work = max_work
        self.v = np.zeros((n, kk))
        self.v[ks, np.arange(kk)] = 1.0  # c(0) = e_k
        self.prev = np.zeros((n, kk))
        self.tot = np.zeros((n, kk))  # S(t)
        self.tv = np.zeros((n, kk))  # TV(t)
        self.imax = np.zeros((n, kk))  # largest initial term in the open interval
        self.cert = np.full(kk, -1, dtype=np.int64)  # per active column
        self.cols = np.arange(kk)  # the active columns, as positions in ks
        self.col_of_row = column_of_row(ks, n)
        self.t = 0
        self.work = 0.0
        self.bp = [0, 1]
        self.tables: list[np.ndarray] = []
        # per column, at its retirement
        self.T = np.zeros(kk, dtype=np.int64)
        self.q_ret = np.zeros(kk, dtype=np.int64)
        self.opened = np.zeros(kk, bool)
        self.certified = np.zeros(kk, bool)
        self.x1, self.x2 = np.zeros((n, kk)), np.zeros((n, kk))
        self.s = np.zeros(kk)
        self.init_bin = np.zeros((n, kk))
        self.acc_inf = np.zeros((n, kk))

    # ---------------------------------------------------------------- the sweep

    def run(self) -> Envelope:
        q = 0
        while True:
            t = self.t
            if t == self.bp[q] and len(self.tables) == q:
                self._open()
            if t == self.bp[q + 1] - 1:
                self._close(q)
                q += 1
                self.bp.append(_next_breakpoint(self.bp[-1]))
            self._retire(q)
            if not len(self.cols):
                break
            target = self.bp[q] if t < self.bp[q] else self.bp[q + 1] - 1
            self._advance(min(target, t + CHECK) - t)
        return self._finish()

    def _advance(self, steps: int) -> None:
        a = self.adj
        advance_columns(
            self.v, self.prev, self.tot, self.tv, self.imax, self.alpha[self.cols],
            self.start.gamma, self.start.structured, a.src, a.first, a.deg, self.col_of_row,
            self.beta, steps, self.t, self.cert,
        )  # fmt: skip
        if steps % 2:
            self.v, self.prev = self.prev, self.v
        self.t += steps
        self.work += steps * len(self.cols) * (self.n + len(a.src))

    def _step(self, c: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """A_k c for the columns ``cols`` (positions in ks)."""
        c = np.ascontiguousarray(c)
        a, out = self.adj, np.empty_like(c)
        apply(c, out, a.src, a.first, a.deg, column_of_row(self.ks[cols], self.n), self.beta)
        return out

    def _open(self) -> None:
        """Interval q starts at the current period."""
        table = np.full((self.n, len(self.ks)), np.nan)
        if self.start.structured:
            self.imax[:] = 0.0
        else:  # ‖e_iᵀ A^t Z‖ ≤ α h k_o R_i(t), decreasing: its value now
            rem = self.mass - self.tot + _slack(self.t, self.mass)
            table[:, self.cols] = self.alpha[self.cols] * self.beta * rem
        self.tables.append(table)

    def _close(self, q: int) -> None:
        """Interval q ends at the current period: the increasing accumulated terms."""
        if self.start.structured:  # the initial term of this last period needs c(t + 1)
            nxt = self._step(self.v, self.cols)
            d = (self.v - nxt) / self.beta
            val = self.alpha[self.cols] * np.abs(self.v - d) + self.start.gamma * np.abs(d)
            self.tables[q][:, self.cols] = np.maximum(self.imax, val)
        if self.t == 0:
            off = np.zeros_like(self.tv)
        else:
            off = self.tv - np.abs(self.v - self.prev) + self.prev  # O(t) = TV(t−1) + c_{t−1}
        acc = self.a_tv * self.tv + self.a_off * off + self.a_slow * self.tot + FLOOR
        acc[self.ks[self.cols], np.arange(len(self.cols))] += self.a_tv + self.a_off  # δ_ik
        self.tables[q][:, self.cols] += acc

    def _retire(self, q: int) -> None:
        """Columns whose recursion can stop: certified monotone, or out of budget."""
        done = self.cert >= 0
        if done.any():  # and R's decay rate settled: Collatz-Wielandt bracket within 10 %
            rem = self.mass - self.tot[:, done] + _slack(self.t, self.mass)
            ratio = self.v[:, done] / rem  # 1 − R_i(t+1)/R_i(t)
            done[done] = ratio.min(axis=0) >= SETTLED * ratio.max(axis=0)
        if self.work > self.max_work or self.t >= MAX_PERIODS:
            done[:] = True
        if not done.any():
            return
        idx = np.flatnonzero(done)
        c = self.cols[idx]
        t, mass, beta = self.t, self.mass, self.beta
        cert = self.cert[idx] >= 0
        c_t = self.v[:, idx]
        rem = mass - self.tot[:, idx] + _slack(t, mass)
        s_r = np.clip(((rem - c_t) / rem).max(axis=0), 0.0, 1.0)  # R(t+1) <= s R(t), A >= 0
        # beyond t, Σ_{m>t}|c_m − c_{m−1}| is c_t for a monotone column. Otherwise it is at
        # most Σ(c_m + c_{m−1}) = 2R(t) − c_t, and at most X = P_k⁻¹|d_t| (d_t = P_k c_t:
        # c_m − c_{m+1} = β A^{m−t} d_t, Σ_j A^j |d_t| = (β P_k)⁻¹ |d_t|); O(t') = TV(t'−1)
        # + c_{t'−1} with c_{t'−1} <= min(R(t), c_t + X) then
        tail_tv = tail_off = c_t
        if not cert.all():
            d_t = np.abs(c_t - self._step(c_t, c)) / beta
            x = np.maximum(grounded_solve(self.graph, self.ks[c], d_t), 0.0)
            mass_tail = 2.0 * rem - c_t
            tail_tv = np.where(cert, c_t, np.minimum(mass_tail, x))
            tail_off = np.where(cert, c_t, np.minimum(mass_tail, x + np.minimum(rem, c_t + x)))
        acc = self.a_tv * (self.tv[:, idx] + tail_tv) + self.a_off * (self.tv[:, idx] + tail_off)
        acc += self.a_slow * mass + FLOOR
        acc[self.ks[c], np.arange(len(c))] += self.a_tv + self.a_off
        # the initial term beyond t: α x1 s^m + γ x2 s^m (see _init_tail). Restart: x1 = R(t).
        # Start: c_{t+m} − d_{t+m} = A^m (c_t − d_t) and d_{t+m} = A^m d_t, and for any z with
        # |z| <= C R(t): |A^m z| <= A^m |z| <= C R(t + m) <= C s^m R(t) (A >= 0)
        x1, x2 = rem, np.zeros_like(rem)
        if self.start.structured:
            d0 = (c_t - self._step(c_t, c)) / beta
            x1 = (np.abs(c_t - d0) / rem).max(axis=0) * rem
            x2 = (np.abs(d0) / rem).max(axis=0) * rem
        self.T[c], self.certified[c], self.q_ret[c] = t, cert, q
        self.opened[c] = len(self.tables) == q + 1
        self.x1[:, c], self.x2[:, c], self.s[c] = x1, x2, s_r
        self.acc_inf[:, c] = acc
        if self.opened[c].any():
            self.init_bin[:, c] = (
                self.imax[:, idx] if self.start.structured else self.tables[q][:, c]
            )
        keep = ~done
        for name in ("v", "prev", "tot", "tv", "imax"):  # x[:, mask] is Fortran-ordered
            setattr(self, name, np.ascontiguousarray(getattr(self, name)[:, keep]))
        self.cols, self.cert = self.cols[keep], self.cert[keep]
        self.col_of_row = column_of_row(self.ks[self.cols], self.n)

    # ---------------------------------------------------------------- the tails

    def _init_tail(self, m: np.ndarray, sel: np.ndarray) -> np.ndarray:
        """The initial term m periods after retirement, for the columns ``sel``."""
        with np.errstate(under="ignore"):
            decay = self.s[sel] ** m
        return (self.tail_alpha[sel] * self.x1[:, sel] + self.start.gamma * self.x2[:, sel]) * decay

    def _finish(self) -> Envelope:
        """Complete every interval after each column's retirement from its tail, and
        add intervals until the initial term has decayed to a negligible level."""
        T = self.T
        init0 = self._init_tail(np.zeros_like(T), np.ones(len(T), bool))
        init_max = init0.max(axis=0)
        target = np.maximum(1e-4 * self.acc_inf.min(axis=0), 1e-15)
        bp = _extend_breakpoints(self.bp, T, init_max, target, self.s)
        n, kk = self.n, len(self.ks)
        while len(self.tables) < len(bp):
            self.tables.append(np.full((n, kk), np.nan))
        for q in range(len(bp)):
            here = (self.q_ret == q) & self.opened  # retired inside interval q
            if here.any():
                top = np.maximum(self.init_bin[:, here], init0[:, here])
                self.tables[q][:, here] = top + self.acc_inf[:, here]
            after = bp[q] > T  # retired before interval q
            if after.any():
                self.tables[q][:, after] = (
                    self._init_tail(bp[q] - T[after], after) + self.acc_inf[:, after]
                )
        bad = ~np.isfinite(self.alpha)
        for table in self.tables:
            table[:, bad] = np.inf
            assert not np.isnan(table).any()
        return Envelope(bp, self.tables, T.copy(), self.certified.copy())


def column_envelope(
    graph: Graph,
    ko: float,
    h: float,
    start: Start,
    mu_coef: tuple[float, float, float],
    rule: str = "l1",
    max_work: float = MAX_WORK,
) -> Envelope:
    """The envelope of ⁱμ_k = (initial term) + a_tv(δ + TV) + a_off(δ + O) + a_slow S
    (eqs. L1, D) for every monitored robot k of ``graph``, ``mu_coef`` = (a_tv, a_off,
    a_slow), the initial term as ``start`` says (:class:`Start`, ``alpha`` per robot).

    Robots that do not reach every robot (M_k not positive stable) get +inf. A graph
    invariant under rotation is swept for k = 0 only.
    """
    check_nonnegative(graph, ko, h, rule)
    n = graph.n
    finite = reaches_all(graph)
    ks = np.flatnonzero(finite)
    if len(ks) == 0:
        return _unbounded(n)
    alpha = np.asarray(start.alpha, float)
    circulant = bool(finite.all()) and rotation_invariant(graph) and bool(np.all(alpha == alpha[0]))
    if circulant:
        ks = ks[:1]
    sub = Start(alpha[ks], start.gamma, start.structured)
    env = _ColumnSweep(graph, h * ko, ks, sub, mu_coef, max_work).run()
    return _expand(env, n, ks, circulant)


def _unbounded(n: int) -> Envelope:
    """No robot reaches every other one: +inf for every pair, from the start."""
    return Envelope(
        np.zeros(1, np.int64), [np.full((n, n), np.inf)], np.zeros(n, np.int64), np.zeros(n, bool)
    )


def _expand(env: Envelope, n: int, ks: np.ndarray, circulant: bool) -> Envelope:
    """Tables for the monitored robots ``ks`` as (N, N) arrays on the robot axis."""
    if len(ks) == n:
        return env
    steps = np.zeros(n, dtype=np.int64)
    cert = np.zeros(n, bool)
    if circulant:  # [f(M_k)]_{ik} = [f(M_0)]_{(i − k) mod N, 0}
        idx = (np.arange(n)[:, None] - np.arange(n)[None, :]) % n
        tables = [t[:, 0][idx] for t in env.table]
        steps[:], cert[:] = env.steps[0], env.certified[0]
    else:
        tables = []
        for t in env.table:
            full = np.full((n, n), np.inf)
            full[:, ks] = t
            tables.append(full)
        steps[ks], cert[ks] = env.steps, env.certified
    return Envelope(env.bp, tables, steps, cert)


class _Enveloped(Thresholds):
    """A rule stored as an :class:`Envelope` after every (re)start."""

    #: ē is raised to the compensation's own offset ‖G‖Φ̄ + 2η̄ (l1, block_row)
    covers_compensation = True

    def __init__(self, drift_bound: float | None = None) -> None:
        self.drift_param = drift_bound

    def reset(self, config: TeamConfig, x_m0: np.ndarray, prior: np.ndarray) -> None:
        """Read h, k_o, η̄, ξ̄, ē and G, and compute the rule on the team's graph. h is the
        observers' step: the control period, or a round of the network (the rules hold at
        the rounds exactly as they do every period on the ideal network)."""
        self.h = config.observer_period
        self.G = np.asarray(config.G, float)
        self.ko, self.eta_bar, self.xi_bar = config.ko, config.eta_bar, config.xi_bar
        self.drift = float(
            self.drift_param
            if self.drift_param is not None
            else getattr(config, "drift_bound", 0.0)
        )
        self.n_dim = np.shape(x_m0)[1]
        self.drift_given = self.drift
        if self.covers_compensation and config.fdir and config.compensate:
            # with the compensation applied, D_k = G φ̂_k − η_k + η_k(0): ē must cover it
            phi_bar = estimator_gain(  # the fault estimator runs every control period
                config.K, config.G, config.dt, self.eta_bar, self.xi_bar, lag=config.lag
            )
            self.drift = max(self.drift, compensation_offset(self.G, phi_bar, self.eta_bar))
        self._setup(config)
        self._begin(config.graph, self._structured(config.graph.n, config.initial_error_bound), 0.0)

    def _setup(self, config: TeamConfig) -> None:
        """Rule-specific constants (before the first restart)."""

    def _structured(self, n: int, y0: float) -> Start:
        raise NotImplementedError

    def _begin(self, graph: Graph, start: Start, t0: float) -> None:
        self.graph, self.t0, self.start = graph, t0, start
        self.env = self._envelope(graph, start)
        self._lo, self._hi, self._current = 0, -1, self.env.table[0]

    def _envelope(self, graph: Graph, start: Start) -> Envelope:
        raise NotImplementedError

    def restart(self, graph: Graph, y0: np.ndarray, t0: float) -> None:
        """Start anew at ``t0`` on ``graph`` from any initial errors with
        max_i ‖ⁱỹ_k(t0)‖ ≤ ``y0[k]``: the residual's initial part −P_k ỹ_k then has rows
        within ‖P_k‖_∞ y0_k = max_l(2 d_l + δ_lk) y0_k."""
        deg = graph.in_degree()
        row = np.maximum(2.0 * deg.max(), 2.0 * deg + 1.0) if graph.n else deg
        self._begin(graph, Start(np.asarray(y0, float) * row), t0)

    def drop(self, p: int, graph: Graph, t: float) -> None:
        """Restart on the reduced graph from the residuals' bound at ``t``.

        For a healthy robot k the rule bounds every ‖ˡr_k(t)‖ by ˡμ_k(t); the initial
        part of the new residual is −P'_k ỹ'_k(t), whose row l differs from the old
        −(P_k ỹ_k)_l = ˡr_k − δ_lk η_k by −(ᵖỹ_k − ˡỹ_k) when p was an in-neighbour of l, and
        by + (ʲỹ_k − ˡỹ_k) for each in-neighbour j that l gained when the survivors were
        re-wired around p (``graph`` holds j → l, the old one j → p → l); ỹ_k = 1 η_kᵀ −
        P_k⁻¹ r_k gives ‖ˡỹ_k − ʲỹ_k‖ ≤ Σ_m |[P_k⁻¹]_lm − [P_k⁻¹]_jm| ᵐμ_k for any j.
        """
        mu = np.array(self.mu(t), dtype=float)
        rows = mu + self._residual_extra() * np.eye(len(mu))
        old = self.graph
        old_index = np.delete(np.arange(old.n), p)  # the survivors' old numbers
        gained = set(graph.edges) - set(old.without(p).edges)
        pairs = [(i, p) for j, i in old.edges if j == p]  # the links that went with p
        pairs += [(int(old_index[i]), int(old_index[j])) for j, i in sorted(gained)]
        if pairs:
            diff = _inverse_row_differences(old, pairs)  # (L, N, N): [pair, m, k]
            with np.errstate(invalid="ignore"):
                spread = np.nansum(np.abs(diff) * mu[None], axis=1)  # Σ_m |ΔG| μ_mk
            spread[~np.isfinite(diff).all(axis=1)] = np.inf
            for (l, _), extra in zip(pairs, spread, strict=True):
                rows[l] += extra
        keep = old_index
        alpha = rows[np.ix_(keep, keep)].max(axis=0)
        self._begin(graph, Start(alpha), t)

    def _residual_extra(self) -> float:
        """δ_lk term of −(P_k ỹ_k)_l = ˡr_k − δ_lk η_k (η̄ for l1, 0 for drive)."""
        return 0.0

    def _period(self, t: float) -> int:
        return max(round((t - self.t0) / self.h), 0)

    def mu(self, t: float) -> np.ndarray:
        """ⁱμ_k(t) (M, M): rows i observe, columns k are monitored (a bound valid for the
        whole interval of periods that contains t)."""
        j = self._period(t)
        if not self._lo <= j < self._hi:
            env = self.env
            q = env.index(j)
            self._current = env.table[q]
            self._lo = int(env.bp[q])
            self._hi = int(env.bp[q + 1]) if q + 1 < len(env.bp) else 2**62
        return self._current


def grounded_solve(
    graph: Graph,
    ks: np.ndarray,
    rhs: np.ndarray,
    transpose: bool = False,
    q_inv: np.ndarray | None = None,
) -> np.ndarray:
    """X[:, b] = P_k⁻¹ rhs[:, b] (P_k⁻ᵀ with ``transpose``), k = ``ks[b]``, P_k = L + e_k e_kᵀ.

    On a strongly connected graph Q = L + 1 1ᵀ/N is invertible and P_k = Q + U Vᵀ with
    U = [e_k, 1], V = [e_k, −1/N]: Woodbury with one dense inverse of Q serves every k
    (N³ once, then N K; ``q_inv``: Q⁻¹ already computed, :func:`q_inverse`). Otherwise
    each P_k is solved on its own (k must reach every robot, so that P_k is invertible).
    """
    n = graph.n
    lap = graph.laplacian()
    rhs = np.asarray(rhs, float)
    if not graph.is_strongly_connected():
        out = np.empty_like(rhs)
        for b, k in enumerate(ks):
            pk = lap.copy()
            pk[k, k] += 1.0
            out[:, b] = np.linalg.solve(pk.T if transpose else pk, rhs[:, b])
        return out
    qi = q_inverse(graph) if q_inv is None else q_inv
    if transpose:  # P_kᵀ = Qᵀ + V Uᵀ: U and V swap roles
        qi, u2, v2 = qi.T, -1.0 / n, 1.0
    else:
        u2, v2 = 1.0, -1.0 / n
    y = qi @ rhs
    w1 = qi[:, ks]  # Q⁻¹ e_k
    w2 = qi.sum(axis=1) * u2  # Q⁻¹ (u2 1)
    c11 = 1.0 + qi[ks, ks]
    c12 = w2[ks]
    c21 = v2 * w1.sum(axis=0)
    c22 = 1.0 + v2 * w2.sum()
    r1 = y[ks, np.arange(len(ks))]
    r2 = v2 * y.sum(axis=0)
    det = c11 * c22 - c12 * c21
    a1 = (c22 * r1 - c12 * r2) / det
    a2 = (-c21 * r1 + c11 * r2) / det
    return y - w1 * a1 - w2[:, None] * a2


def q_inverse(graph: Graph) -> np.ndarray:
    """Q⁻¹, Q = L + 1 1ᵀ/N, of a strongly connected graph (:func:`grounded_solve`)."""
    return np.linalg.inv(graph.laplacian() + 1.0 / graph.n)


def _inverse_row_differences(graph: Graph, pairs: list[tuple[int, int]]) -> np.ndarray:
    """[P_k⁻¹]_{l,m} − [P_k⁻¹]_{j,m} for each pair (l, j) of ``pairs``, every m and k: (L, N, N)
    as [pair, m, k]; NaN where k does not reach every robot (P_k singular)."""
    n = graph.n
    ks = np.flatnonzero(reaches_all(graph))
    out = np.full((len(pairs), n, n), np.nan)
    q_inv = q_inverse(graph) if graph.is_strongly_connected() else None  # once for every pair
    for a, (l, j) in enumerate(pairs):
        e = np.zeros((n, len(ks)))
        e[l] += 1.0
        e[j] -= 1.0
        out[a][:, ks] = grounded_solve(graph, ks, e, transpose=True, q_inv=q_inv)
    return out
