"""The decision of eq. 39 (onboard/decision.py): a row it would leave as it is is skipped,
and only such a row; a row the pass finds quiet from its residual is such a row."""

from __future__ import annotations

import numpy as np
import pytest
from numba import njit

from dftc_mujoco.onboard.decision import (
    ISOLATION,
    Decision,
    DecisionRecord,
    bound_squares,
    decide,
    decide_row,
    entry_share,
    quiet_row,
    quiet_sums,
    timer_type,
    unchanged_row,
)
from dftc_mujoco.onboard.observer import row_norms
from dftc_mujoco.onboard.thresholds.paper import ThresholdRecord, dense_thresholds


@njit
def _skipped(r, th, i, dec):
    return unchanged_row(r, th, i, dec)


@njit
def _quiet(row, n, th, i, dec):
    return quiet_row(row, n, th, i, dec)


@njit
def _quiet_sums(row, n, th, i, dec):
    """:func:`quiet_sums` with the count residual_row takes in its loop, over every block but
    robot i's own (whose final entries the pass tests apart): the least the count can be."""
    scale = np.empty(row.shape[0])
    bound_squares(th, n, scale)
    half, over = entry_share(th, i, n), 0
    for a in range(row.shape[0]):
        if a // n != i:
            r = row[a]
            over += not r * r < half * scale[a]
    return quiet_sums(over, row, n, th, i, dec)


@njit
def _norms(row, n, m):
    """‖ⁱr_k‖ of robot i's residual row, as the pass takes them."""
    out = np.empty(m)
    row_norms(row, n, out)
    return out


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
    rest_rows = (timer == -top).all(axis=1) & ~flag.any(axis=1) & ~raised_rows  # settled_row
    return DecisionRecord(timer, flag, need, mode, isolated, raised, raised_rows, rest_rows)


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
            # what at_rest answers is the row's own state once every row has been decided
            top = max(need, 1)
            settled = (dec.timer == -top).all(axis=1) & ~dec.flag.any(axis=1) & ~dec.raised_rows
            assert np.array_equal(dec.rest_rows, settled), (need, round_)
        assert raised > 0  # flags rose (and fell), not only rows at rest


def _around_rows(rng, mu: np.ndarray, n: int) -> np.ndarray:
    """Residual rows (M, M·n) whose k-th block has a norm at and around μ_k: μ itself in one
    component (its square the float μ·μ), the neighbouring floats of μ, a relative 1e-12
    either side, μ split 0.6 : 0.8 over two components, well below; and now and then 0,
    NaN or inf."""
    m = mu.shape[0]
    pick = rng.integers(0, 8, mu.shape)
    with np.errstate(invalid="ignore"):
        v = np.select(
            [pick == 0, pick == 1, pick == 2, pick == 3, pick == 4, pick == 5],
            [mu, np.nextafter(mu, np.inf), np.nextafter(mu, 0.0), mu * (1 + 1e-12),
             mu * (1 - 1e-12), mu * 0.5],
            default=mu * rng.uniform(0.0, 1.4, mu.shape),
        )  # fmt: skip
    v[rng.random(mu.shape) < 0.03] = 0.0
    v[rng.random(mu.shape) < 0.03] = np.nan
    v[rng.random(mu.shape) < 0.03] = np.inf
    v *= np.where(rng.random(mu.shape) < 0.5, -1.0, 1.0)
    rows = np.zeros((m, m, n))
    at = rng.integers(0, n, mu.shape)
    split = (rng.random(mu.shape) < 0.3) & np.isfinite(v)
    i, k = np.nonzero(~split)
    rows[i, k, at[i, k]] = v[i, k]
    i, k = np.nonzero(split)
    rows[i, k, at[i, k]] = 0.6 * v[i, k]
    rows[i, k, (at[i, k] + 1) % n] = 0.8 * v[i, k]
    return rows.reshape(m, m * n)


@pytest.mark.parametrize("n", [2, 3])
def test_a_row_quiet_by_its_residual_is_one_its_norms_leave_as_it_is(n):
    """Wherever :func:`quiet_row` finds a row quiet from robot i's residual (the squares
    compared as they are computed), the norms the pass would take from it
    (:func:`~dftc_mujoco.onboard.observer.row_norms`) leave the row as it is
    (:func:`unchanged_row`), exactly: residual norms at μ, at its neighbouring floats and
    split over two components, thresholds from 1e-170 (squares below the normal floats) to
    1e170 (squares beyond them), +inf, NaN, zero and negative entries of a rule's array; and
    a row at rest well below its thresholds is found quiet. (A tolerance of 1e-12 the wrong
    way, or no test of μ ≥ 0, makes this fail.)"""
    rng = np.random.default_rng(46 + n)
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
            rows = np.zeros((m, m * n))
            rows[:, ::n] = np.where(np.isfinite(mu), mu * 0.5, 1.0)
        else:
            with np.errstate(over="ignore"):
                rows = _around_rows(rng, mu, n)
        for i in range(m):
            norms = _norms(rows[i], n, m)
            if _quiet(rows[i], n, th, i, dec):
                quiet += 1
                assert _skipped(norms, th, i, dec), (case, i, mu[i], rows[i])
            elif clean and _skipped(norms, th, i, dec):
                loud_at_rest += 1
    assert quiet > 1000
    assert loud_at_rest == 0  # at rest and well below: found quiet from the squares


@pytest.mark.parametrize("n", [2, 3])
def test_a_row_quiet_by_the_residual_loop_s_count_is_quiet_by_its_squares(n):
    """Wherever :func:`quiet_sums` finds a row quiet from the count the residual's loop
    takes (each entry against its share of eq. 40's bound), :func:`quiet_row` finds it
    quiet too, hence its norms leave it as it is: residual norms at μ, at its neighbouring
    floats and split over two components, factors from 1e-170 to 1e170 (beyond the range
    the loop tests, :data:`~dftc_mujoco.onboard.decision.TESTED`), unbounded robots
    (b_k = +inf), zero, NaN and inf entries; and rows at rest well below their thresholds
    are found quiet by the count alone. (Without the margin below the bound, or without the
    own block's test, this fails.)"""
    rng = np.random.default_rng(61 + n)
    quiet = clean_quiet = clean_rows = 0
    for case in range(3000):
        m = int(rng.integers(1, 9))
        clean = case % 5 == 0
        scales = [-3, 0, 2] if clean else [-170, -60, -3, 0, 2, 60, 170]
        th = _factored(rng, m)
        th = th._replace(coef=th.coef * 10.0 ** rng.choice(scales))
        if case % 7 == 3:  # an observer without in-neighbours: cᵢ = 0
            th.coef[rng.integers(0, m)] = 0.0
        with np.errstate(invalid="ignore"):
            mu = np.outer(th.coef, th.bound)
        dec = _record(rng, m, int(rng.integers(0, 30)), case % 3, settled=0.8)
        if clean:
            rows = np.zeros((m, m * n))
            rows[:, ::n] = np.where(np.isfinite(mu), mu * 0.5, 1.0)
        else:
            with np.errstate(over="ignore", invalid="ignore"):
                rows = _around_rows(rng, np.where(np.isnan(mu), 1.0, mu), n)
                # blocks whose every component sits at μ/√n, or a hair either side: the
                # count's share of the bound at its edge
                even = rng.random((m, m)) < 0.3
                hair = rng.choice([0.0, 1e-16, -1e-16, 1e-13, -1e-13, 1e-10, -1e-10], (m, m))
                edge = mu / np.sqrt(n) * (1.0 + hair)
                blocks = rows.reshape(m, m, n)
                blocks[even] = edge[even][:, None]
        for i in range(m):
            if _quiet_sums(rows[i], n, th, i, dec):
                quiet += 1
                assert _quiet(rows[i], n, th, i, dec), (case, i, mu[i], rows[i])
                clean_quiet += clean
            elif clean and dec.rest_rows[i] and th.coef[i] > 0:
                clean_rows += 1
    assert quiet > 500
    assert clean_quiet > 100 and clean_rows == 0  # at rest, well below: found by the count


def test_a_flag_moved_by_hand_before_the_blocks_update_is_decided_as_before():
    """A plug-in decision that raises a flag by hand in a row at rest, then calls the block's
    update, has that flag lowered by the window at the next round, as when the test of a
    row at rest read the row's flags: the block reads every row's rest anew first."""
    d = Decision.standalone(3, window=0.03, dt=0.01)
    below, mu = np.zeros((3, 3)), np.ones((3, 3))
    for _ in range(6):  # every row at rest: timers at -need, flags down
        d.update(below, mu)
    assert d.record().rest_rows.all()
    d.flag[0, 1] = True  # by hand, as a subclass might
    d.update(below, mu)
    assert not d.flag.any()
