"""Δt_d of eq. 46: when a constant fault is guaranteed detected, robot by robot.

:func:`predicted_delays` sweeps the signature of a constant fault, h·fault·S_ik(j), against
twice the steady threshold of any rule; :func:`detection_horizon` makes Δt_d,max of it
(``fdir.dt_d_max = "auto"``)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ...core.graph import Graph, reaches_all, rotation_invariant
from ..applied import distinct_lags
from ..block import TeamConfig
from .envelope import CHECK, MAX_PERIODS, _slack
from .kernels import Adjacency, advance_crossing, column_of_row

#: Δt_d: crossings are found period by period up to this much work, then bounded
EXACT_CROSSING_WORK = 5e8
#: the horizon's sweep stops after this many column-entry updates. It is not the
#: envelope's smaller budget: a crossing left unfound is bounded far more loosely than an
#: envelope's tail (on the 20 × 20 k-nearest grid, l1's Δt_d,max of 77 s becomes 8 hours
#: with the envelope's budget)
MAX_WORK = 4e9


def predicted_delays(
    graph: Graph,
    ko: float,
    h: float,
    mu_steady: np.ndarray,
    fault: float,
    max_work: float = MAX_WORK,
    lag: float | np.ndarray = 0.0,
    limit: float = np.inf,
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

    ``lag`` = τ > 0: robot k's drive answers with a first-order lag (``TeamConfig.lag``,
    modelled onboard, ``onboard/applied.py``). A stop then does not take its velocity at
    once: the velocity decays through the lag (v₀ e^(−t/τ); the slow test base: τ = 2.49 s
    measured against its calibrated 2.50) while the robot's own drive model goes on
    predicting the commanded one, so y_m,k drifts by at least h·fault·(1 − r^m) in period m
    after onset (r = e^(−h/τ)), and the signature is h·fault·W_ik(j), W(j) = Σ_{m<j}
    (1 − r^m) A_k^(j−1−m) e_k = S(j) − E(j), E(j) = Σ_{m<j} r^(j−1−m) A_k^m e_k (monotone in
    the drift: A_k ≥ 0). Its crossings are swept as S's are, and bounded past a
    column's certificate from the decay of R and E (:func:`_lagged_tail`). A team whose
    robots model different lags (``lag`` (M,)) gets each column k with robot k's own.

    ``limit`` [s]: the sweep goes no further; a pair that has not crossed by then (and whose
    crossing is not bounded yet) reads the first period past it, a lower bound of its delay.
    """
    if np.ndim(lag) > 0:
        lags = np.asarray(lag, dtype=float)
        out = np.full((graph.n, graph.n), np.inf)
        for tau in distinct_lags(lags):
            mine = lags == tau
            delays = predicted_delays(graph, ko, h, mu_steady, fault, max_work, tau, limit)
            out[:, mine] = delays[:, mine]
        return out
    lag = float(lag)
    n = graph.n
    beta = h * ko
    last = math.floor(limit / h) + 1 if np.isfinite(limit) else math.inf  # periods
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
        periods = _crossing_periods(adj, beta, np.array([0]), need0, ok0, max_work, h, lag, last)
        idx = (np.arange(n)[:, None] - np.arange(n)[None, :]) % n
        return periods[:, 0][idx] * h
    out = np.full((n, n), np.inf)
    ks = np.flatnonzero(crossable.any(axis=0))
    if len(ks):
        out[:, ks] = _crossing_periods(
            adj, beta, ks, need[:, ks], crossable[:, ks], max_work, h, lag, last
        )
    return out * h


def _crossing_periods(
    adj: Adjacency,
    beta: float,
    ks: np.ndarray,
    need: np.ndarray,
    crossable: np.ndarray,
    max_work: float,
    h: float = 0.0,
    lag: float = 0.0,
    last: float = math.inf,
) -> np.ndarray:
    """First period j with S_ik(j) ≥ need (N, K) for the columns ``ks`` (inf if never); with
    a drive's ``lag`` > 0, with W_ik(j) ≥ need (:func:`predicted_delays`). The sweep stops
    at period ``last`` (inf: no such limit, only the budget's): a crossing not found or
    bounded by then reads ``last``."""
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
    lagged = lag > 0.0
    r = float(np.exp(-h / lag)) if lagged else 0.0
    est = np.zeros((n, kk) if lagged else (0, kk))  # E of the lagged drift
    t, work = 0, 0.0
    while len(cols):
        advance_crossing(
            v, prev, tot, est, r, goal, when, adj.src, adj.first, adj.deg,
            column_of_row(ks[cols], n), beta, CHECK, t, cert,
        )  # fmt: skip
        t += CHECK
        work += CHECK * len(cols) * (n + len(adj.src))
        open_ = (when < 0) & np.isfinite(goal)
        crossed = ~open_.any(axis=0)
        out_of_budget = work > max_work or t >= MAX_PERIODS
        at_last = t >= last
        # past its certificate a column's crossings are bounded from R's decay; while the
        # sweep is cheap it goes on to find them exactly
        done = crossed | ((cert >= 0) & (work > EXACT_CROSSING_WORK)) | out_of_budget | at_last
        if not done.any():
            continue
        idx = np.flatnonzero(done)
        c = cols[idx]
        got = when[:, idx] >= 0
        result[:, c] = np.where(got, when[:, idx], result[:, c])
        if at_last:  # the rest lie past the last period sought: that is all that is asked
            open_at_last = ~got & np.isfinite(goal[:, idx])
            result[:, c] = np.where(open_at_last, float(last), result[:, c])
            break
        # the rest from R(t + m) <= s^m R(t) (A_k >= 0)
        rem = mass - tot[:, idx] + _slack(t, mass)
        s = np.clip(((rem - v[:, idx]) / rem).max(axis=0), 0.0, 1.0)
        g = goal[:, idx]
        late = ~got & np.isfinite(g) & (s < 1.0)
        if lagged:
            # c(t) ≤ sc c(t − 1) entry by entry gives A_k c(t) ≤ sc c(t) (A_k ≥ 0); +inf
            # where an entry of c(t − 1) is 0 and its c(t) is not
            newest, before = v[:, idx], prev[:, idx]
            with np.errstate(divide="ignore", invalid="ignore"):
                ratio = np.where(before > 0.0, newest / before, np.where(newest > 0.0, np.inf, 0.0))
            sc = ratio.max(axis=0)
            e_now = est[:, idx] + _slack(t, mass)  # E's rounding, as R's
            m = _lagged_tail(rem, e_now, s, r, mass - g, late, newest, sc)
        else:
            with np.errstate(divide="ignore", invalid="ignore"):
                m = np.ceil(np.log((mass - g) / rem) / np.log(s))
        result[:, c] = np.where(late, t + np.maximum(m, 0.0), result[:, c])
        keep = ~done
        v, prev, tot, goal, when, est = (
            np.ascontiguousarray(a[:, keep]) for a in (v, prev, tot, goal, when, est)
        )
        cert, cols = cert[keep], cols[keep]
    return result


#: where :func:`_lagged_tail` splits the newer columns: fractions of m, and lags before m
_SPLITS = (0.05, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9)
_SPLIT_LAGS = (1, 2, 3, 4, 6, 8, 12, 16, 24, 32)


def _lagged_tail(
    rem: np.ndarray,
    est: np.ndarray,
    s: np.ndarray,
    r: float,
    room: np.ndarray,
    late: np.ndarray,
    col: np.ndarray,
    sc: np.ndarray,
) -> np.ndarray:
    """Periods m after a certificate by which a lagged drift's W has surely crossed (N, K):
    mass − W(t + m) = R(t + m) + E(t + m), R(t + m) ≤ s^m R(t) and E(t + m) = r^m E(t) +
    Σ_{q<m} r^(m−1−q) c(t + q). The newer columns c(t + q) are bounded two ways: by
    sc^q c(t) (``col``; A_k c(t) ≤ sc c(t) when c(t) ≤ sc c(t − 1), A_k ≥ 0), which gives
    c(t) (sc^m − r^m) / (sc − r) where sc ≤ 1 (``sc`` (K,), +inf if no such sc); and, split
    at p ≤ m, those before p weigh at most r^(m−p) and sum to at most R(t), those from p on
    sum to at most R(t + p) ≤ s^p R(t). The first m on a grid growing 2 % a step (p a few
    fractions of m, and m less a few lags) at which the lesser bound is at most ``room`` =
    mass − need, where ``late`` (+inf where it never is within
    :data:`~.envelope.MAX_PERIODS`)."""
    out = np.full(rem.shape, np.inf)
    open_ = late.copy()
    lag = -1.0 / np.log(r) if r > 0.0 else 0.0  # τ in periods
    m = 1
    while m <= MAX_PERIODS and open_.any():
        splits = {max(1, round(f * m)) for f in _SPLITS}
        splits |= {m - round(k * lag) for k in _SPLIT_LAGS if round(k * lag) < m}
        split = np.minimum.reduce([r ** (m - p) + s**p for p in splits]) * rem
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            near = np.abs(sc - r) < 1e-12
            geo = np.where(near, m * r ** (m - 1), (sc**m - r**m) / (sc - r)) * col
        geo = np.where(sc <= 1.0, geo, np.inf)  # a growing column bounds nothing here
        bound = s**m * rem + r**m * est + np.minimum(split, geo)
        hit = open_ & (bound <= room)
        out[hit] = m
        open_ &= ~hit
        m = max(m + 1, int(m * 1.02))
    return out


def detection_horizon(
    cfg: TeamConfig, graph: Graph, thresholds: Any, members: np.ndarray | None = None
) -> tuple[float, dict[str, Any]]:
    """Δt_d,max and how it was found: the scenario's, or (``"auto"``) eq. 46 for the
    reference fault on ``graph`` with the steady thresholds of ``thresholds`` (the team's
    block, whatever its rule; recomputed on the new graph at each exclusion, whose
    ``members`` are the robots left)."""
    if cfg.dt_d_max != "auto":
        return float(cfg.dt_d_max), {"value": float(cfg.dt_d_max), "source": "scenario"}
    # the signature of a constant fault comes from the columns A_k^j e_k alone (no tables)
    steady = np.array(thresholds.mu(1e9), dtype=float)
    # a stop of a robot whose drive lags its command reaches its velocity through the lag
    lag = cfg.lag if np.ndim(cfg.lag) == 0 or members is None else np.asarray(cfg.lag)[members]
    # sought for as long as the run lasts: a longer Δt_d,max changes nothing in it
    delays = predicted_delays(
        graph, cfg.ko, cfg.dt, steady, cfg.reference_fault, lag=lag, limit=cfg.run_length
    )
    # the teammates decide the exclusion (eq. 43): robot k's judgement of itself is
    # reported, not waited for (its own residual sits on its noise and drift offset)
    self_ok = bool((np.diag(delays) <= cfg.run_length).all())
    np.fill_diagonal(delays, 0.0)
    worst = float(delays.max()) + cfg.detection_window
    longer = bool(np.isfinite(worst) and worst > cfg.run_length)
    info: dict[str, Any] = {
        "source": "analysis (eq. 46)",
        "reference_fault": cfg.reference_fault,
        "predicted_delays_max": worst if np.isfinite(worst) and not longer else None,
        "self_detection_guaranteed": self_ok,
    }
    if longer:  # the value is then a lower bound, past the run's end
        info["longer_than_the_run"] = True
    lags = distinct_lags(lag)
    if max(lags) > 0:  # the prediction's premise: a stop's velocity decays through the lag
        info["drive_lag"] = lags[0] if len(lags) == 1 else lags
    if np.isfinite(worst):
        info["value"] = worst
        return worst, info
    info["value"] = 5.0
    info["warning"] = (
        f"a constant fault of {cfg.reference_fault:g} m/s is not guaranteed detectable by "
        "every teammate with these thresholds (eq. 46); Δt_d,max falls back to 5 s"
    )
    return 5.0, info
