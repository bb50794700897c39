"""The decision of eq. 39 (onboard/decision.py): a row it would leave as it is is skipped,
and only such a row; a row the pass finds quiet from the squares of its norms is such a
row."""

from __future__ import annotations

import numpy as np
import pytest
from numba import njit

from dftc_mujoco.onboard.decision import (
    ISOLATION,
    DecisionRecord,
    decide,
    decide_row,
    quiet_row,
    timer_type,
    unchanged_row,
)
from dftc_mujoco.onboard.thresholds.paper import ThresholdRecord, dense_thresholds


@njit
def _skipped(r, th, i, dec):
    return unchanged_row(r, th, i, dec)


@njit
def _quiet(sq, th, i, dec):
    return quiet_row(sq, th, i, dec)


@njit
def _every_row(r_norm, th, dec):
    """:func:`decide` without the skip: :func:`decide_row` on every row."""
    count = 0
    for i in range(r_norm.shape[0]):
        count += decide_row(r_norm[i], th, i, dec)
    return count


def _factored(rng, m: int) -> ThresholdRecord:
    """Eq. 40's factors, with a robot whose bound is unbounded (λ_k = 0) now and then."""
    finite = rng.random(m) > 0.15
    bound = np.where(finite, rng.uniform(0.5, 1.5, m), np.inf)
    none = np.zeros(m)
    return ThresholdRecord(
        np.zeros((0, 0)), rng.uniform(0.5, 1.5, m), bound, finite, none, none, none,
        np.full(1, -1.0), 0.01,
    )  # fmt: skip


def _record(rng, m: int, need: int, mode: int, settled: float) -> DecisionRecord:
    """A decision's state with a share ``settled`` of its rows at rest (flags down, timers
    at -max(need, 1)), the others anywhere within the timers' range."""
    top = max(need, 1)
    timer = rng.integers(-top, top + 1, (m, m)).astype(timer_type(need))
    flag = rng.random((m, m)) < 0.3
    rest = rng.random(m) < settled
    timer[rest], flag[rest] = -top, False
    # a row at rest but for one flag still up (an exclusion's re-plan could leave one)
    late = rest & (rng.random(m) < 0.1)
    flag[late, rng.integers(0, m)] = True
    raised = flag & (rng.random((m, m)) < 0.5)
    raised_rows = raised.any(axis=1) | (rng.random(m) < 0.05)
    isolated = np.where(rng.random(m) < 0.5, rng.integers(0, m, m), -1)
    return DecisionRecord(timer, flag, need, mode, isolated, raised, raised_rows)


def _copy(dec: DecisionRecord) -> DecisionRecord:
    return DecisionRecord(*(v.copy() if isinstance(v, np.ndarray) else v for v in dec))


def _residuals(rng, th: ThresholdRecord, m: int, above: float) -> np.ndarray:
    """Norms around the thresholds: each above its own with probability ``above``, with
    a NaN (a robot that left) and an inf now and then."""
    if th.dense.shape[0]:
        mu = th.dense
    else:
        mu = np.outer(th.coef, th.bound)
        mu[~np.isfinite(mu)] = 1.0
    r = mu * np.where(rng.random((m, m)) < above, 1.5, 0.5)
    r[rng.random((m, m)) < 0.02] = np.nan
    r[rng.random((m, m)) < 0.01] = np.inf
    return r


@pytest.mark.parametrize("need", [0, 1, 2, 20, 200])
def test_a_row_is_skipped_only_where_the_decision_would_leave_it_as_it_is(need):
    """Wherever the test says a row is left as it is, the decision of that row changes
    nothing (timers, flags, the flags raised, the isolated robot) and raises nothing, in
    every isolation mode; and the test says so for most of the rows at rest below their
    thresholds, the healthy team's usual round, with dense thresholds and eq. 40's factors
    alike."""
    rng = np.random.default_rng(need)
    skipped = rows_at_rest = 0
    for case in range(300):
        m = int(rng.integers(1, 9))
        mode = case % 3  # pairwise, exclusive, exclusive with history
        th = _factored(rng, m) if case % 2 else dense_thresholds(rng.uniform(0.5, 1.5, (m, m)))
        dec = _record(rng, m, need, mode, settled=0.7)
        r = _residuals(rng, th, m, above=0.02 if case % 4 else 0.3)
        for i in range(m):
            if not _skipped(r[i], th, i, dec):
                continue
            skipped += 1
            after = _copy(dec)
            raised = decide_row(r[i], th, i, after)
            assert raised == 0
            for name, a, b in zip(DecisionRecord._fields, dec, after, strict=True):
                if isinstance(a, np.ndarray):
                    assert np.array_equal(a, b), (case, i, name)
        top = max(need, 1)
        at_rest = (dec.timer == -top).all(axis=1) & ~dec.flag.any(axis=1) & ~dec.raised_rows
        rows_at_rest += int(at_rest.sum())
    assert skipped > 0.4 * rows_at_rest > 100


@pytest.mark.parametrize("mode", list(ISOLATION))
def test_the_decision_with_its_skip_gives_every_row_s_numbers(mode):
    """Over 300 rounds of residuals near their thresholds, a faulty robot's above them for 20
    rounds in every 50, :func:`decide` (which skips the rows left as they are) and the
    decision of every row give the same timers, flags, flags raised and isolated robots,
    round by round, and raise as many flags."""
    rng = np.random.default_rng(ISOLATION[mode] + 7)
    for need in (1, 3, 8):
        m = 6
        th = _factored(rng, m)
        th = th._replace(finite=np.ones(m, bool), bound=np.abs(th.bound).clip(0.5, 1.5))
        dec = _record(rng, m, need, ISOLATION[mode], settled=1.0)
        dec.raised[:] = False
        dec.raised_rows[:] = False
        dec.isolated[:] = -1
        ref, raised = _copy(dec), 0
        for round_ in range(300):
            r = _residuals(rng, th, m, above=0.02 if round_ % 50 < 40 else 0.6)
            if 10 <= round_ % 50 < 30:  # a faulty robot: every teammate sees it above
                r[:, round_ // 50 % m] = np.inf
            count = decide(r, th, dec)
            assert count == _every_row(r, th, ref)
            raised += count
            for name, a, b in zip(DecisionRecord._fields, dec, ref, strict=True):
                if isinstance(a, np.ndarray):
                    assert np.array_equal(a, b), (need, round_, name)
        assert raised > 0  # flags rose (and fell), not only rows at rest


def _around_squares(rng, mu: np.ndarray) -> np.ndarray:
    """Squares of norms at and around (μ_k)² as the pass computes it: the float μ·μ itself,
    its neighbouring floats, a relative 1e-12 either side, well below, and now and then
    0, NaN or inf."""
    p = mu * mu
    pick = rng.integers(0, 8, mu.shape)
    sq = np.select(
        [pick == 0, pick == 1, pick == 2, pick == 3, pick == 4, pick == 5],
        [p, np.nextafter(p, np.inf), np.nextafter(p, 0.0), p * (1 + 1e-12), p * (1 - 1e-12),
         p * 0.25],
        default=p * rng.uniform(0.0, 2.0, mu.shape),
    )  # fmt: skip
    sq[rng.random(mu.shape) < 0.03] = 0.0
    sq[rng.random(mu.shape) < 0.03] = np.nan
    sq[rng.random(mu.shape) < 0.03] = np.inf
    return sq


def test_a_row_quiet_by_its_squares_is_one_its_norms_leave_as_it_is():
    """Wherever :func:`quiet_row` finds a row quiet from the squares of its norms, the norms
    themselves (their square roots, as the pass takes them) leave the row as it is
    (:func:`unchanged_row`), exactly: squares at the float μ·μ and its neighbours, thresholds
    from 1e-170 (squares below the normal floats) to 1e170 (squares beyond them), +inf,
    NaN, zero and negative entries of a rule's array; and a row at rest well below its
    thresholds is found quiet. (A tolerance of 1e-12 the wrong way, or no test of μ ≥ 0,
    makes this fail.)"""
    rng = np.random.default_rng(46)
    quiet = loud_at_rest = 0
    for case in range(3000):
        m = int(rng.integers(1, 9))
        clean = case % 5 == 0  # well below thresholds of everyday sizes
        scales = [-3, 0, 2] if clean else [-170, -100, -3, 0, 2, 100, 170]
        scale = 10.0 ** rng.choice(scales)
        if case % 2:
            th = _factored(rng, m)
            th = th._replace(coef=th.coef * scale)
            mu = np.outer(th.coef, th.bound)
        else:
            mu = rng.uniform(0.5, 1.5, (m, m)) * scale
            odd = rng.random((m, m)) + clean  # no odd entries when clean
            mu[odd < 0.03] = np.inf
            mu[(odd >= 0.03) & (odd < 0.06)] = np.nan
            mu[(odd >= 0.06) & (odd < 0.09)] = 0.0
            mu[(odd >= 0.09) & (odd < 0.12)] *= -1.0
            th = dense_thresholds(mu)
        dec = _record(rng, m, int(rng.integers(0, 30)), case % 3, settled=0.8)
        if clean:
            sq = np.where(np.isfinite(mu), mu * mu * 0.25, 1.0)
        else:
            with np.errstate(over="ignore"):
                sq = _around_squares(rng, mu)
        with np.errstate(invalid="ignore"):
            norms = np.sqrt(sq)
        for i in range(m):
            if _quiet(sq[i], th, i, dec):
                quiet += 1
                assert _skipped(norms[i], th, i, dec), (case, i, mu[i], sq[i])
            elif clean and _skipped(norms[i], th, i, dec):
                loud_at_rest += 1
    assert quiet > 1000
    assert loud_at_rest == 0  # at rest and well below: found quiet from the squares
