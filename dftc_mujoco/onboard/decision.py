"""The decision of eq. 39 with the time window of Remark 5.2.

:class:`Decision` (block) raises robot i's flag on robot k when ‖ⁱr_k‖ > ⁱμ_k has held for
``window`` seconds, and lowers it after as long below; with ``isolation = "exclusive"``
(eq. 39's second clause) a robot flags k only while no other robot is above its threshold.
The rule is the compiled :func:`decide`, which the compiled period calls too."""

from __future__ import annotations

import functools
from typing import NamedTuple

import numpy as np
from numba import njit

from ..core.graph import Graph
from .block import Block, TeamConfig
from .thresholds.paper import dense_thresholds, threshold_at

#: ``fdir.isolation`` -> the mode of :func:`decide`
ISOLATION = {"pairwise": 0, "exclusive": 1, "exclusive_history": 2}


@functools.cache
def count_for(window: float, dt: float) -> int:
    """How many rounds a condition must hold to last ``window`` s: the smallest c with
    dt + dt + … (c times, in floating point) ≥ window − 1e-9, the sum the float timers of
    Remark 5.2 used to keep, so the integer timers switch at the very same round."""
    if not window / dt < 1e6:  # beyond any run (inf: never): the float sum is not kept
        return int(min(np.ceil(window / dt), np.iinfo(np.int32).max))
    acc, c = 0.0, 0
    while acc < window - 1e-9:
        acc += dt
        c += 1
    return c


def timer_type(need: int) -> type:
    """The integer type of the timers for a window of ``need`` rounds: they stay within
    ±max(need, 1) (:func:`tick`), so one byte holds the usual windows (the default 0.2 s at
    0.01 s: 20 rounds). The timers are the decision's one N × N array read and written every
    round: at N = 1000, 2 MB a round in int8 against 8 MB in int32."""
    return np.int8 if need <= np.iinfo(np.int8).max else np.int32


@njit(inline="always")
def tick(c, over, need):  # pragma: no cover - compiled
    """A timer after one more round: rounds above (> 0) or not above (< 0) the threshold,
    counted from 1 at each change of side and kept within ±max(need, 1)."""
    top = max(need, 1)
    up = min(max(c, 0) + 1, top)  # 1 after a change of side, else c + 1
    down = max(min(c, 0) - 1, -top)  # -1 after a change of side, else c - 1
    return up if over else down  # no branch: a loop of these is vectorised


@njit(inline="always")
def move_flag(i, k, c, flag, need, isolated, raised):  # pragma: no cover - compiled
    """Raise robot i's flag on k once its timer ``c`` counts ``need`` rounds above, lower it
    after ``need`` rounds not above; returns 1 when it was raised now."""
    if c > 0 and c >= need and not flag[i, k]:
        flag[i, k] = True
        raised[i, k] = True
        if isolated[i] < 0:
            isolated[i] = k
        return 1
    if c < 0 and -c >= need and flag[i, k]:
        flag[i, k] = False
    return 0


@njit(inline="always")
def settled_row(i, dec):  # pragma: no cover - compiled
    """Whether robot i's row of the decision is at rest, read from the row itself: no flag
    raised in it at the last round, every flag down and every timer at -max(need, 1) (below
    its threshold for the whole window and more). :func:`decide_row` keeps the answer in
    ``rest_rows`` (:func:`at_rest`), so a round reads the row's timers and flags only where
    it decides."""
    if dec.raised_rows[i]:
        return False
    timer, flag, m, top = dec.timer, dec.flag, dec.flag.shape[1], max(dec.need, 1)
    low = 0
    for k in range(m):  # counted without a branch: a loop the compiler vectorises
        low += (timer[i, k] == -top) & (not flag[i, k])
    return low == m


@njit(inline="always")
def at_rest(i, dec):  # pragma: no cover - compiled
    """Whether robot i's row of the decision is at rest (:func:`settled_row`), as
    :func:`decide_row` left it: ``rest_rows[i]``. :func:`decide_row` writes the answer after
    each move of a row's timers and flags, so in the compiled period, where nothing else
    moves them, the answer is the row's; a record made anew or resized starts with every
    row not at rest, which costs its first round a decision per row and nothing else, and
    the block's :meth:`Decision.update` reads every row anew first (:func:`settle_rows`).
    At N = 1000 the test read 2 MB of timers and flags from memory a round (2026-12-01:
    the pass 0.3-0.6 ms faster on one core)."""
    return dec.rest_rows[i]


@njit(inline="always")
def unchanged_row(r, th, i, dec):  # pragma: no cover - compiled
    """Whether :func:`decide_row` would leave robot i's row as it is: the row at rest
    (:func:`at_rest`) and no residual above its threshold now. Its loops then write the
    same timers and move no flag, in every isolation mode (with nothing above, nothing is
    blocked). A healthy team's usual round: the test reads the row and writes nothing.
    ``r[k] > cᵢ b_k`` is the comparison of :func:`decide_row`'s loop; robot i's own
    ⁱμ_i = (cᵢ + 1) b_i + η̄ is no smaller (none of its factors is negative), so its own
    test adds nothing.

    The loop over the robots calls it before :func:`decide_row`: written inside
    :func:`decide_row` the same test made the decision slower (0.31 µs a row at N = 160,
    against 0.24 without the test and 0.16 with it in the caller's loop; :func:`decide` on
    a team at rest, 2026-11-28)."""
    if not at_rest(i, dec):
        return False
    m, over = r.shape[0], 0
    if th.dense.shape[0]:  # a rule's array: row i of it
        for k in range(m):
            over += r[k] > th.dense[i, k]
    else:  # eq. 40's factors (+inf where λ_k = 0: cᵢ b_k is inf or nan, never exceeded)
        ci, bound = th.coef[i], th.bound
        for k in range(m):
            over += r[k] > ci * bound[k]
    return over == 0


@njit(inline="always")
def quiet_row(row, n, th, i, dec):  # pragma: no cover - compiled
    """Whether robot i's row is at rest (:func:`at_rest`) and every ‖ⁱr_k‖², computed from
    robot i's residual ``row`` (M·n,) as :func:`~.observer.row_norms` computes it before
    its square roots, lies below (ⁱμ_k)²: then :func:`unchanged_row` on the norms the pass
    would take is true, and the pass skips them: their square roots
    (2026-11-28: 6-10 % of the pass at N = 1000) and their store: each square is compared
    as it is computed, from the residual. The squares are written out in the loops: the
    same sum in a helper stopped the compiler vectorising them (the test on 1000 rows took
    0.93-0.95 ms instead of 0.42-0.50 ms, 2026-11-28).

    Exact, with no tolerance: x < fl(μ·μ) with μ ≥ 0 gives x < μ² (x is a float below the
    float nearest μ², so below μ² itself), hence √x < μ, and the square root rounded to
    the nearest float is at most μ, itself a float: ``np.sqrt(x) > μ`` is false. That holds
    for subnormal squares too (rounded, not flushed to zero), and where μ·μ overflows (a
    finite x has √x below every such μ); μ = +inf is never exceeded; a NaN x or μ, or a
    negative μ, fails the test (the row takes the square roots)."""
    if not at_rest(i, dec):
        return False
    m, below, dense = dec.flag.shape[1], 0, th.dense.shape[0] > 0
    if n == 2 and dense:  # the plane, a rule's array: row i of it
        mus = th.dense[i]
        for k in range(m):
            sq = row[2 * k] ** 2 + row[2 * k + 1] ** 2
            mu = mus[k]
            below += (sq < mu * mu) & (mu >= 0.0)
    elif n == 2:  # the plane, eq. 40's factors: ⁱμ_k = cᵢ b_k, the float unchanged_row compares
        ci, bound = th.coef[i], th.bound
        for k in range(m):
            sq = row[2 * k] ** 2 + row[2 * k + 1] ** 2
            mu = ci * bound[k]
            below += (sq < mu * mu) & (mu >= 0.0)
    else:  # any n: one loop for either kind of thresholds (not the plane's hot path)
        for k in range(m):
            sq = 0.0
            for d in range(n):
                sq += row[k * n + d] ** 2
            mu = th.dense[i, k] if dense else th.coef[i] * th.bound[k]
            below += (sq < mu * mu) & (mu >= 0.0)
    return below == m


#: how far below eq. 40's bound the test in the residual's loop keeps each entry (a relative
#: 1e-9: far more than the few roundings between it and :func:`quiet_row`'s comparison)
SHORT = 1.0 - 1e-9
#: the thresholds' factors the test in the residual's loop takes (beyond: not tested there)
TESTED = (1e-50, 1e50)


@njit(inline="always")
def bound_squares(th, n, scale):  # pragma: no cover - compiled
    """The per-entry scale of the test of a row at rest in the residual's own loop
    (:func:`~.observer.residual_row`, :func:`quiet_sums`), into ``scale`` (M·n,): with eq.
    40's factors, b_k² at every entry of robot k's block (+inf where b_k = +inf); NaN (no
    entry passes) with a rule's array, or where b_k is not within :data:`TESTED`."""
    m = scale.shape[0] // n
    factored = th.dense.shape[0] == 0
    lo, hi = TESTED
    for k in range(m):
        b = th.bound[k] if factored else np.nan
        v = b * b if lo < b < hi else (np.inf if b == np.inf else np.nan)
        for d in range(n):
            scale[k * n + d] = v


@njit(inline="always")
def entry_share(th, i, n):  # pragma: no cover - compiled
    """What each of the n components of robot i's residual block may reach, as a share of
    b_k² (:func:`bound_squares`): c_i²·:data:`SHORT`/n, so that all n below it put the
    block's square below (cᵢ b_k)², the off-diagonal ⁱμ_k² of eq. 40; NaN (no entry
    passes) with a rule's array or where c_i is not within :data:`TESTED`."""
    if th.dense.shape[0]:
        return np.nan
    ci = th.coef[i]
    lo, hi = TESTED
    return ci * ci * SHORT / n if lo < ci < hi else np.nan


@njit(inline="always")
def quiet_sums(over, row, n, th, i, dec):  # pragma: no cover - compiled
    """Whether robot i's row is quiet (:func:`quiet_row` would say so), from the count
    ``over`` that :func:`~.observer.residual_row` took in its own loop: the row at rest
    (:func:`at_rest`), no entry at or above its share of b_k² (:func:`entry_share`,
    :func:`bound_squares`), and robot i's own block, whose measurement term comes after
    that loop, below (cᵢ b_i)² exactly as :func:`quiet_row` compares it. The pass then
    needs no loop over the row's squares (2026-12-01, N = 1000 on one core: 0.27-0.52 ms a
    pass less than with the rest bits alone).

    Exact: with every component r_d² < fl(h·b_k²), h = fl(cᵢ² (1 − 10⁻⁹) / n), the block's
    square Σ r_d² lies below cᵢ² b_k² (1 − 10⁻⁹)(1 + 10 ε) and so below the float
    (cᵢ b_k)·(cᵢ b_k) that :func:`quiet_row` compares, by far more than its roundings
    (ε = 2⁻⁵³; every factor within :data:`TESTED`, so nothing is subnormal or overflows:
    b_k = +inf passes finite entries, as eq. 40's +inf is never exceeded, and any NaN
    fails). False is always safe: :func:`quiet_row` follows."""
    if over or not at_rest(i, dec):
        return False
    acc = 0.0
    for d in range(n):  # the own block's square, as row_norms and quiet_row take it
        acc += row[i * n + d] ** 2
    mu = th.coef[i] * th.bound[i]
    return (acc < mu * mu) & (mu >= 0.0)


@njit(inline="always")
def decide_row(r, th, i, dec):  # pragma: no cover - compiled
    """Eq. 39 with Remark 5.2's window for robot i's row (its own residuals' norms ``r``,
    (M,), and its thresholds only) and the decision's record ``dec``; returns how many
    flags it raised. ``th`` is this round's thresholds
    (:func:`~.thresholds.paper.threshold_at`). See :func:`decide`.

    Pairwise (the common case) the timers move in a loop without branches, against row i
    of a rule's array or eq. 40's factors (ⁱμ_k = cᵢ b_k off the diagonal; where b_k = +inf,
    cᵢ b_k is inf or nan and the comparison false, as with the +inf of
    :func:`~.thresholds.paper.threshold_at`), and only a row whose flags may change takes
    the loop that moves them (the loop that reads each ⁱμ_k through ``threshold_at`` made
    l1 at N = 100 cost 590 µs a period instead of 290)."""
    timer, flag, need, mode, isolated, raised = (
        dec.timer,
        dec.flag,
        dec.need,
        dec.exclusive,
        dec.isolated,
        dec.raised,
    )
    m = r.shape[0]
    if dec.raised_rows[i]:  # the flags raised at the last round are not raised now
        raised[i, :] = False
        dec.raised_rows[i] = False
    count = 0
    if mode == 0:
        changes, top = 0, max(need, 1)  # c >= top: c > 0 and c >= need (a flag to be up)
        ti, fi = timer[i], flag[i]
        if th.dense.shape[0]:  # a rule's array: row i of it
            mu = th.dense[i]
            for k in range(m):
                c = tick(ti[k], r[k] > mu[k], need)
                ti[k] = c
                changes += (c >= top) != fi[k]
        else:  # eq. 40's factors
            ci, bound, own = th.coef[i], th.bound, ti[i]
            for k in range(m):
                c = tick(ti[k], r[k] > ci * bound[k], need)
                ti[k] = c
                changes += (c >= top) != fi[k]
            c = tick(own, r[i] > threshold_at(th, i, i), need)  # k = i: its own ⁱμ_i
            ti[i] = c
            changes += (c >= top) != fi[i]
        if changes:
            for k in range(m):
                count += move_flag(i, k, timer[i, k], flag, need, isolated, raised)
    else:
        n_over = 0
        if mode > 0:
            for k in range(m):
                if r[k] > threshold_at(th, i, k):
                    n_over += 1
        for k in range(m):  # in order: mode 2 blocks the k after one isolated in this round
            blocked = (mode > 0 and n_over > 1) or (
                mode == 2 and isolated[i] >= 0 and isolated[i] != k
            )
            over = r[k] > threshold_at(th, i, k) and not blocked
            timer[i, k] = tick(timer[i, k], over, need)
            count += move_flag(i, k, timer[i, k], flag, need, isolated, raised)
    if count:
        dec.raised_rows[i] = True
    dec.rest_rows[i] = settled_row(i, dec)  # what at_rest answers until the next decision
    return count


@njit(cache=True)
def decide(r_norm, th, dec):  # pragma: no cover - compiled
    """Robot i flags k once ‖ⁱr_k‖ > ⁱμ_k has held ``dec.need`` rounds (the window); lowers
    it after as many not above.

    Updates the record's ``timer`` and ``flag`` (M, M) in place (eq. 39 with Remark 5.2's
    window); ``raised`` (M, M) marks the flags raised now. Returns how many were raised.
    ``exclusive`` (:data:`ISOLATION`): 0, pairwise, robot i judges each k on its own; 1,
    exclusive, robot i counts ‖ⁱr_k‖ > ⁱμ_k only while all its other residuals are at or
    below their thresholds (eq. 39's second clause, instant by instant); 2, exclusive with
    history, eq. 39 as the paper states it: also only if robot i has flagged no other robot
    since the last restart. ``isolated[i]`` (M,) is the robot robot i flagged first since
    then (−1: none), kept for mode 2. Each robot's row is its own decision
    (:func:`decide_row`, which the compiled period calls robot by robot).
    """
    count = 0
    for i in range(r_norm.shape[0]):
        if not unchanged_row(r_norm[i], th, i, dec):
            count += decide_row(r_norm[i], th, i, dec)
    return count


@njit(cache=True)
def settle_rows(dec):  # pragma: no cover - compiled
    """Every row's ``rest_rows`` read anew from the row itself (:func:`settled_row`): for a
    caller that may have moved timers or flags outside :func:`decide_row` (the block's
    :meth:`Decision.update`, which a plug-in's subclass may call after changing them)."""
    for i in range(dec.rest_rows.shape[0]):
        dec.rest_rows[i] = settled_row(i, dec)


class DecisionRecord(NamedTuple):
    """What the compiled period (:mod:`.period`) reads and writes of the decision."""

    timer: np.ndarray  # (M, M) int8 or int32 (timer_type): rounds above (> 0) or not (< 0)
    flag: np.ndarray  # (M, M) robot i flags robot k
    need: int  # rounds a condition must hold: the window (:func:`count_for`)
    exclusive: int  # the isolation mode (ISOLATION)
    isolated: np.ndarray  # (M,) the robot each isolates, or -1
    raised: np.ndarray  # (M, M) the flags raised this period
    raised_rows: np.ndarray  # (M,) rows of ``raised`` with a flag in them
    rest_rows: np.ndarray  # (M,) rows at rest (settled_row) when last decided; False: not known


class Decision(Block):
    """Debounced flags: robot i flags k after ``window`` s above ⁱμ_k (eq. 39, Remark 5.2).

    ``window`` defaults to the scenario's ``fdir.detection_window`` and
    ``isolation`` to ``fdir.isolation``: ``"pairwise"`` (robot i judges each k on
    its own), ``"exclusive"`` (eq. 39's second clause read instant by instant: robot i
    isolates k only while its other residuals stay below their thresholds) or
    ``"exclusive_history"`` (eq. 39 as the paper states it: and only if robot i has
    flagged no other robot since the last exclusion). Override
    :meth:`update` to try another decision rule; row i may use only robot i's
    own residuals and thresholds.
    """

    kind = "decision"

    def __init__(self, window: float | None = None, isolation: str | None = None) -> None:
        self.window_param = window
        self.isolation_param = isolation

    def reset(self, config: TeamConfig, x_m0: np.ndarray, prior: np.ndarray) -> None:
        """All timers at zero, nobody flagged."""
        self.dt = config.observer_period  # it decides at every round of the observers
        self.window = config.detection_window if self.window_param is None else self.window_param
        isolation = config.isolation if self.isolation_param is None else self.isolation_param
        if isolation not in ISOLATION:
            raise ValueError(f"isolation must be one of {', '.join(ISOLATION)}, got {isolation!r}")
        self.exclusive = ISOLATION[isolation]
        n = len(x_m0)
        self.isolated = np.full(n, -1, dtype=np.int64)
        self._allocate(n)

    def _allocate(self, n: int) -> None:
        # np.full writes every page now: np.zeros leaves them to the first read, and the
        # decision of eq. 39 then paid page faults every period (31-35 ms at N = 1000)
        kind = timer_type(count_for(self.window, self.dt))
        self.timer: np.ndarray = np.full((n, n), 0, dtype=kind)
        self.flag = np.full((n, n), False)
        self._raised = np.full((n, n), False)
        self._raised_rows = np.full(n, False)
        self._rest_rows = np.full(n, False)  # at_rest: no row known at rest yet

    @classmethod
    def standalone(cls, n: int, window: float, dt: float) -> Decision:
        """A decision block for ``n`` robots outside any team."""
        d = cls(window)
        d.dt, d.window, d.exclusive = dt, window, 0
        d.isolated = np.full(n, -1, dtype=np.int64)
        d._allocate(n)
        return d

    def update(self, r_norm: np.ndarray, mu: np.ndarray) -> np.ndarray:
        """Feed ‖ⁱr_k‖ and ⁱμ_k (M, M); return the flags raised at this instant (M, M) bool."""
        th = dense_thresholds(np.ascontiguousarray(mu, float))
        record = self.record()
        settle_rows(record)  # a subclass may have moved timers or flags since the last round
        decide(np.ascontiguousarray(r_norm, float), th, record)
        return self._raised

    def record(self) -> DecisionRecord:
        """The state the compiled period updates (the thresholds come in their own record)."""
        return DecisionRecord(
            self.timer,
            self.flag,
            count_for(self.window, self.dt),
            self.exclusive,
            self.isolated,
            self._raised,
            self._raised_rows,
            self._rest_rows,
        )

    @property
    def raised(self) -> np.ndarray:
        """(M, M) the flags raised at the last update."""
        return self._raised

    def drop(self, p: int, graph: Graph, t: float) -> None:
        """Forget robot at position ``p`` (vectors resized after an exclusion); the isolation
        history starts again (the fault it recorded has been handled)."""
        self._raised_rows = np.full(len(self.flag) - 1, False)
        self._rest_rows = np.full(len(self.flag) - 1, False)  # decided anew at the next round
        for name in ("timer", "flag", "_raised"):
            a = getattr(self, name)
            setattr(self, name, np.delete(np.delete(a, p, axis=0), p, axis=1))
        self.isolated = np.full(len(self.flag), -1, dtype=np.int64)


@njit(cache=True)
def flagged_by_teammates(flag, out):  # pragma: no cover - compiled
    """out[k] = some robot i ≠ k flags robot k (``flag`` read row by row, in memory order:
    column by column was 12× slower at N = 1000)."""
    for k in range(flag.shape[1]):
        out[k] = False
    for i in range(flag.shape[0]):
        for k in range(flag.shape[1]):
            if flag[i, k] and i != k:
                out[k] = True


class NoDecision(Decision):
    """No detection and no isolation: nobody is ever flagged, so nobody is excluded
    (``[onboard] decision = "none"``). The rest of the DFTC runs as the paper's, fault
    compensation included (``fdir.compensate = false`` switches it off too): the method a
    campaign compares fault detection with, to show what it buys."""

    def update(self, r_norm: np.ndarray, mu: np.ndarray) -> np.ndarray:
        """No flag, whatever the residuals."""
        self._raised[...] = False
        return self._raised
