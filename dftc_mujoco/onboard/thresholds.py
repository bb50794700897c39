"""Threshold rules beside the paper's eq. 40, derived for the discrete-time observer.

``docs/thresholds.md`` has the derivations. The observer runs by forward Euler at
the control period h; with P_k = L + e_k e_kᵀ, β = h k_o, A_k = I − β P_k,
c_t = [A_k^t]_{ik} (≥ 0 when β (d_max + 1) ≤ 1), d_t = (c_t − c_{t+1})/β,
TV(t) = Σ_{1≤m≤t} |c_m − c_{m−1}|, O(t) = TV(t − 1) + c_{t−1} (O(0) = 0) and
S(t) = Σ_{m<t} c_m → 1/β:

* ``l1`` (eq. L1): with ‖η_k‖ ≤ η̄ and the drift y_k(t) − y_k(0) = S_k(t) + E_k(t) of
  y_k = x_k − ∫u_k split into a slow part (‖ΔS_k‖ ≤ h ξ̄ per period) and a bounded
  offset (‖E_k‖ ≤ ē: actuator lag, compensation),
  ⁱμ_k(t) = |c_t − d_t| ε̄ + |d_t| η̄ + η̄(δ_ik + TV_ik(t)) + ē(δ_ik + O_ik(t)) + h ξ̄ S_ik(t).
* ``drive`` (eq. D): robot k's measured y_m,k − y_m,k(0) = G φ̂_k exactly (the fault
  estimator's algebra), a pure offset of size ‖G‖ Φ̄:
  ⁱμ_k(t) = |c_t − d_t| (ε̄ + η̄) + ‖G‖ Φ̄ (δ_ik + O_ik(t)).
* ``block_row`` (eq. B): ⁱμ_k(t) = ‖e_iᵀ P_k A_k^t‖ y0_k + h(k_o η̄ + √N ξ̄) Σ_{j<t}
  ‖e_iᵀ P_k A_k^j‖ + δ_ik η̄ + ē(δ_ik + O_ik(t)).

The initial terms above are those of the start (every robot's first estimates have a
known structure); after an exclusion l1 and drive restart from the residuals' bound
(:meth:`_Enveloped.drop`). ``l1`` and ``drive`` need only the columns A_k^j e_k: one
sparse recursion per monitored robot, batched and compiled (:mod:`.columns`), stopped
once every entry of the column is certified non-increasing (exact tails from there
on) or at a work budget (rigorous looser tails). The thresholds are stored as an
envelope on a geometric grid of periods (a bound for every period of each interval),
not per period. ``block_row`` needs the rows of P_k A_k^j, N² numbers per monitored
robot and period: it is exact and limited to teams of at most :data:`BLOCK_ROW_MAX`
robots.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from ..errors import ScenarioError
from ..graph import Graph
from .block import TeamConfig
from .columns import (
    TINY,
    Adjacency,
    advance_columns,
    advance_crossing,
    apply,
    column_of_row,
    ratio_max,
    reaches_all,
    rotation_invariant,
)
from .fdir import Thresholds

#: single-period bins up to this period, then each bin RATIO times longer
FIRST_BINS = 8
RATIO = 1.25
#: a sweep stops after this many periods even if a column is not certified (then a
#: looser, still rigorous tail bound is used), or after MAX_WORK column-entry updates
MAX_PERIODS = 1_000_000
MAX_WORK = 4e9
SETTLED = 0.9  # a column stops once min_i/max_i of c_i/R_i (its decay rate) is above this
CHECK = 32  # periods between two looks at the certificates (even: see _crossing_periods)
#: Δt_d: crossings are found period by period up to this much work, then bounded
EXACT_CROSSING_WORK = 5e8
#: block_row tabulates N² row norms per monitored robot and period (~N³ per period)
BLOCK_ROW_MAX = 64
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
            f"to be non-negative, i.e. ko * control_period * (max in-degree + 1) <= 1; got "
            f"{ko:g} * {h:g} * {dmax + 1:g} = {h * ko * (dmax + 1):g}. Lower gains.ko or "
            'physics.control_period, or use thresholds = "paper"'
        )


# --------------------------------------------------------------------------- column sweep


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
    circulant = bool(finite.all()) and rotation_invariant(graph) and np.all(alpha == alpha[0])
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


# --------------------------------------------------------------------------- rules


class _Enveloped(Thresholds):
    """A rule stored as an :class:`Envelope` after every (re)start."""

    #: ē is raised to the compensation's own offset ‖G‖Φ̄ + 2η̄ (l1, block_row)
    covers_compensation = True

    def __init__(self, drift_bound: float | None = None) -> None:
        self.drift_param = drift_bound

    def reset(self, config: TeamConfig, x_m0: np.ndarray, prior: np.ndarray) -> None:
        """Read h, k_o, η̄, ξ̄, ē and G, and compute the rule on the team's graph."""
        self.h = config.dt
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
            phi_bar = estimator_gain(
                config.K, config.G, self.h, self.eta_bar, self.xi_bar, lag=config.lag
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
        −(P_k ỹ_k)_l = ˡr_k − δ_lk η_k only by ˡỹ_k − ᵖỹ_k when p was an in-neighbour of l,
        and ỹ_k = 1 η_kᵀ − P_k⁻¹ r_k gives ‖ˡỹ_k − ᵖỹ_k‖ ≤ Σ_m |[P_k⁻¹]_lm − [P_k⁻¹]_pm| ᵐμ_k.
        """
        mu = np.array(self.mu(t), dtype=float)
        rows = mu + self._residual_extra() * np.eye(len(mu))
        old = self.graph
        out_p = [i for j, i in old.edges if j == p]
        if out_p:
            diff = _inverse_row_differences(old, p, np.array(out_p))  # (L, N, N): [l, m, k]
            with np.errstate(invalid="ignore"):
                spread = np.nansum(np.abs(diff) * mu[None], axis=1)  # Σ_m |ΔG| μ_mk
            spread[~np.isfinite(diff).all(axis=1)] = np.inf
            rows[out_p] += spread
        keep = np.delete(np.arange(old.n), p)
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
    graph: Graph, ks: np.ndarray, rhs: np.ndarray, transpose: bool = False
) -> np.ndarray:
    """X[:, b] = P_k⁻¹ rhs[:, b] (P_k⁻ᵀ with ``transpose``), k = ``ks[b]``, P_k = L + e_k e_kᵀ.

    On a strongly connected graph Q = L + 1 1ᵀ/N is invertible and P_k = Q + U Vᵀ with
    U = [e_k, 1], V = [e_k, −1/N]: Woodbury with one dense inverse of Q serves every k
    (N³ once, then N K). Otherwise each P_k is solved on its own (k must reach every
    robot, so that P_k is invertible).
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
    qi = np.linalg.inv(lap + 1.0 / n)
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


def _inverse_row_differences(graph: Graph, p: int, rows: np.ndarray) -> np.ndarray:
    """[P_k⁻¹]_{l,m} − [P_k⁻¹]_{p,m} for l in ``rows``, every m and k: (L, N, N) as [l, m, k];
    NaN where k does not reach every robot (P_k singular)."""
    n = graph.n
    ks = np.flatnonzero(reaches_all(graph))
    out = np.full((len(rows), n, n), np.nan)
    for a, l in enumerate(rows):
        e = np.zeros((n, len(ks)))
        e[l] += 1.0
        e[p] -= 1.0
        out[a][:, ks] = grounded_solve(graph, ks, e, transpose=True)
    return out


class L1(_Enveloped):
    """The ℓ1 rule (``[onboard] thresholds = "l1"``): scales to large teams.

    A bound when each robot's measurement noise is within η̄ and the drift of
    y_k = x_k − ∫u_k is a slow part (within h ξ̄ per period) plus an offset within
    ``drift_bound`` = ē [m] (default: the team's ``drift_bound``, else 0):
    ⁱμ_k(t) = (initial term) + η̄(δ_ik + TV_ik(t)) + ē(δ_ik + O_ik(t)) + h ξ̄ S_ik(t)
    (``docs/thresholds.md``, eq. L1). At the start the initial term is
    |c_t − d_t| ε̄ + |d_t| η̄ (ε̄ = ``initial_error_bound``); after an exclusion it
    restarts from the residuals' bound (:meth:`drop`). Needs k_o h (d_max + 1) ≤ 1.
    """

    initial_error = "robot"

    def _structured(self, n: int, y0: float) -> Start:
        return Start(np.full(n, y0), self.eta_bar, True)

    def _residual_extra(self) -> float:
        return self.eta_bar

    def _envelope(self, graph: Graph, start: Start) -> Envelope:
        mu = (self.eta_bar, self.drift, self.h * self.xi_bar)
        return column_envelope(graph, self.ko, self.h, start, mu, "l1")


class Drive(_Enveloped):
    """The drive rule (``[onboard] thresholds = "drive"``): the tightest rule here.

    A bound whenever every healthy robot's fault estimate stays within ``phi_bar``
    [m/s] (and its anti-windup does not act): robot k's measured y_m,k moves only as
    G φ̂_k does, an offset of size F = ‖G‖₂ Φ̄, so
    ⁱμ_k(t) = (initial term) + F (δ_ik + O_ik(t)) (eq. D); at the start the initial
    term is |c_t − d_t| (ε̄ + η̄), after an exclusion it restarts from the residuals'
    bound (:meth:`drop`). By default Φ̄ is the ℓ1 gain of the fault estimator's closed
    loop on an ideal plant, from η (bound η̄) and from a velocity mismatch (bound ξ̄)
    to φ̂; on a real robot its own mismatch adds to it (``docs/thresholds.md``).
    Needs k_o h (d_max + 1) ≤ 1.
    """

    initial_error = "robot"
    covers_compensation = False  # Φ̄ is its own premise

    def __init__(self, phi_bar: float | None = None) -> None:
        super().__init__()
        self.phi_bar_param = phi_bar

    def _setup(self, config: TeamConfig) -> None:
        self.phi_bar = (
            float(self.phi_bar_param)
            if self.phi_bar_param is not None
            else estimator_gain(
                config.K, config.G, config.dt, config.eta_bar, config.xi_bar, lag=config.lag
            )
        )
        self.offset = float(np.linalg.norm(self.G, 2)) * self.phi_bar

    def _structured(self, n: int, y0: float) -> Start:
        return Start(np.full(n, y0 + self.eta_bar), 0.0, True)  # ε = (1 − e_k)(a − η)ᵀ

    def _envelope(self, graph: Graph, start: Start) -> Envelope:
        f = self.offset
        return column_envelope(graph, self.ko, self.h, start, (0.0, f, 0.0), "drive")


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


# --------------------------------------------------------------------------- block row


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
    circulant = bool(finite.all()) and rotation_invariant(graph) and np.all(y0 == y0[0])
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


# --------------------------------------------------------------------------- Φ̄, Δt_d


def compensation_offset(G: np.ndarray, phi_bar: float, eta_bar: float) -> float:
    """The drift offset the compensation makes on a healthy robot: ‖G‖₂ Φ̄ + 2η̄.

    With the fault estimator (eqs. 29-31) and the observer fed the same input,
    y_m,k(t) − y_m,k(0) = G φ̂_k(t) exactly, so D_k = G φ̂_k − η_k(t) + η_k(0)
    (``docs/thresholds.md``): l1 and block_row take ē at least this large.
    """
    return float(np.linalg.norm(np.asarray(G, float), 2)) * phi_bar + 2.0 * eta_bar


def estimator_gain(
    K: np.ndarray,
    G: np.ndarray,
    h: float,
    eta_bar: float,
    xi_bar: float,
    steps: int = 100000,
    lag: float = 0.0,
) -> float:
    """Bound of ‖φ̂‖ on a healthy robot (x_m = x + η, mismatch ‖ξ‖ ≤ ξ̄ from its drive model).

    The fault estimator's closed loop (eqs. 28-31 with compensation) is linear in
    the deviation d = x − z and the integral I = ∫e: φ̂ = G⁻¹(d + η + K I),
    d⁺ = d + h(ξ − φ̂ − K(d + η)), I⁺ = I + h(d + η) on an ideal plant (ẋ = ū + ξ). A drive
    with a first-order lag ``lag`` that the robot models (``onboard/applied.py``) delivers
    its command's lagged response: the model cancels the lag of u, but φ̂ reaches the
    plant through the lag too, d⁺ = d + h(ξ − (1 − b)φ̂ − b w − K(d + η)), w⁺ = aφ̂ + (1 − a)w
    (a, b of :func:`~.applied.lag_coefficients`). Returns Σ_t ‖H_η(t)‖₂ η̄ + Σ_t ‖H_ξ(t)‖₂ ξ̄
    (ℓ1 norms of its impulse responses).
    """
    from .applied import lag_coefficients

    K, G = np.asarray(K, float), np.asarray(G, float)
    gi = np.linalg.inv(G)
    n = len(K)
    eye, zero = np.eye(n), np.zeros((n, n))
    a, b = lag_coefficients(lag, h)
    # state s = [d, I] (and w with a lag); φ̂ = C s + D η
    C = np.hstack([gi, gi @ K])
    D = gi
    Ad = np.block([[eye - h * (1 - b) * gi - h * K, -h * (1 - b) * gi @ K], [h * eye, eye]])
    B_eta = np.vstack([-h * (1 - b) * gi - h * K, h * eye])
    B_xi = np.vstack([h * eye, zero])
    if a > 0.0:
        Ad = np.block(
            [
                [Ad, np.vstack([-h * b * eye, zero])],
                [a * gi, a * gi @ K, (1 - a) * eye],
            ]
        )
        C = np.hstack([C, zero])
        B_eta = np.vstack([B_eta, a * gi])
        B_xi = np.vstack([B_xi, zero])
    if np.abs(np.linalg.eigvals(Ad)).max() >= 1.0:
        raise ScenarioError(
            "gains.G, gains.K: the fault estimator's loop is unstable at this control period"
            + (f" with the drive lag of {lag:g} s" if a > 0 else "")
            + "; its compensation has no bound Φ̄ (raise gains.G)"
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
    max_work: float = MAX_WORK,
) -> np.ndarray:
    """ⁱΔt_d (M, M) [s] for a constant, uncompensated fault of size ``fault`` [m/s] on robot k.

    Such a fault moves robot k's measured y_m,k by h·fault every period, so by eq. (1)
    of ``docs/thresholds.md`` its signature at robot i after j periods is
    ‖ⁱf_k‖ = h·fault·S_ik(j), S_ik(j) = Σ_{m<j} [A_k^m]_{ik} (increasing to 1/(h k_o) when
    A_k ≥ 0), and eq. 46 guarantees detection once it reaches 2 ⁱμ_k (the steady
    threshold ``mu_steady``, rows i, columns k). The columns A_k^j e_k are swept (batched,
    :mod:`.columns`) until every pair has crossed or the column is certified monotone;
    then R = 1/(h k_o) − S decays at least as fast as s^m (A R(t) ≤ s R(t), s =
    max_i R_i(t+1)/R_i(t)), which bounds the remaining crossing times from above.
    +inf where fault/k_o ≤ 2 ⁱμ_k (never guaranteed) or robot k does not reach robot i,
    and everywhere when some A_k has a negative entry (h k_o (d_max + 1) > 1): S_ik then
    oscillates and can fall back below 2 ⁱμ_k after crossing it, inside the detection
    window, so no crossing guarantees a flag.
    """
    n = graph.n
    beta = h * ko
    mass = 1.0 / beta
    need = 2.0 * np.asarray(mu_steady, float) / (h * fault)  # [i, k], in units of S
    adj = Adjacency.of(graph)
    if beta * (adj.deg.max() + 1.0) > 1.0 + 1e-12:
        return np.full((n, n), np.inf)
    finite = reaches_all(graph)
    crossable = np.isfinite(need) & finite[None, :] & (need < mass * (1.0 - 1e-12))
    circulant = bool(finite.all()) and rotation_invariant(graph)
    if circulant:  # one column, with the largest need at each offset i − k
        rot = need[(np.arange(n)[:, None] + np.arange(n)[None, :]) % n, np.arange(n)[None, :]]
        need0 = rot.max(axis=1, keepdims=True)
        ok0 = np.isfinite(need0) & (need0 < mass * (1.0 - 1e-12))
        periods = _crossing_periods(adj, beta, np.array([0]), need0, ok0, max_work)
        idx = (np.arange(n)[:, None] - np.arange(n)[None, :]) % n
        return periods[:, 0][idx] * h
    out = np.full((n, n), np.inf)
    ks = np.flatnonzero(crossable.any(axis=0))
    if len(ks):
        out[:, ks] = _crossing_periods(adj, beta, ks, need[:, ks], crossable[:, ks], max_work)
    return out * h


def _crossing_periods(
    adj: Adjacency,
    beta: float,
    ks: np.ndarray,
    need: np.ndarray,
    crossable: np.ndarray,
    max_work: float,
) -> np.ndarray:
    """First period j with S_ik(j) ≥ need (N, K) for the columns ``ks`` (inf if never)."""
    n, kk = adj.n, len(ks)
    mass = 1.0 / beta
    result = np.where(crossable & (need <= 0.0), 0.0, np.inf)
    v = np.zeros((n, kk))
    v[ks, np.arange(kk)] = 1.0
    prev, tot = np.zeros((n, kk)), np.zeros((n, kk))
    goal = np.where(crossable, need, np.inf)
    when = np.where(result == 0.0, 0, -1).astype(np.int64)
    cert = np.full(kk, -1, dtype=np.int64)
    cols = np.arange(kk)
    t, work = 0, 0.0
    while len(cols):
        advance_crossing(
            v, prev, tot, goal, when, adj.src, adj.first, adj.deg,
            column_of_row(ks[cols], n), beta, CHECK, t, cert,
        )  # fmt: skip
        t += CHECK
        work += CHECK * len(cols) * (n + len(adj.src))
        open_ = (when < 0) & np.isfinite(goal)
        crossed = ~open_.any(axis=0)
        out_of_budget = work > max_work or t >= MAX_PERIODS
        # past its certificate a column's crossings are bounded from R's decay; while the
        # sweep is cheap it goes on to find them exactly
        done = crossed | ((cert >= 0) & (work > EXACT_CROSSING_WORK)) | out_of_budget
        if not done.any():
            continue
        idx = np.flatnonzero(done)
        c = cols[idx]
        got = when[:, idx] >= 0
        result[:, c] = np.where(got, when[:, idx], result[:, c])
        # the rest from R(t + m) <= s^m R(t) (A_k >= 0)
        rem = mass - tot[:, idx] + _slack(t, mass)
        s = np.clip(((rem - v[:, idx]) / rem).max(axis=0), 0.0, 1.0)
        g = goal[:, idx]
        with np.errstate(divide="ignore", invalid="ignore"):
            m = np.ceil(np.log((mass - g) / rem) / np.log(s))
        late = ~got & np.isfinite(g) & (s < 1.0)
        result[:, c] = np.where(late, t + np.maximum(m, 0.0), result[:, c])
        keep = ~done
        v, prev, tot, goal, when = (
            np.ascontiguousarray(a[:, keep]) for a in (v, prev, tot, goal, when)
        )
        cert, cols = cert[keep], cols[keep]
    return result
