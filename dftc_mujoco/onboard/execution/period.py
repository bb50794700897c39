"""One control period of the whole team with the paper's blocks, compiled.

This is not a second implementation: it calls, in the order of Fig. 1, the
same compiled functions the blocks call (observer :func:`~.observer.estimate_one`,
:func:`~.observer.residual_row`, :func:`~.observer.advance_one`,
:func:`~.observer.integrate_inputs`; controller :func:`~.controller.collective_one`;
supervisor :func:`~.supervisor.supervise`; fault estimator
:func:`~.fault_estimator.estimate_faults`; decision :func:`~.decision.decide_row`;
thresholds :func:`~.thresholds.paper.threshold_at`), each equation written once (only the
mission's x_d = c + offsets of eq. 14, one addition, is spelled out in both paths). It reads
and writes the blocks' state records (each block's ``record()``, :data:`RECORDS`) and
reaches into no block.

The stages: :func:`begin` (measurements, x_d, u_g,i), :func:`commands` (:func:`act` and
:func:`deliver`: every robot's commands), then one pass over the team's N × N state, robot
by robot (:func:`team_rows`: ⁱx̂, ∫ⁱû_g, then at a round the residual, its norms, the next
ŷ, written to a second buffer the observer swaps in since every robot reads its
in-neighbours' current messages, and the flags), then :func:`integrate`. Once
:func:`begin` has read each robot's own block of the state, the commands and the pass
touch nothing of each other's, and the pass reads nothing the physics changes: a large
team's pass may run in helper threads while the calling thread sends the commands and
steps the physics (:class:`~.sharing.Sharing`). On a network the residual and the decision
run only at the observers' rounds (``PeriodInputs.round_now``), on the messages the links
delivered (``ObserverRecord.links``); every period on the ideal network.

The compiled entries (:data:`team_period_call`, and the stages one by one for a shared
pass) take the records' fields in :data:`RECORDS`' order, written from the records'
definitions (:func:`~.records.flat_call`). :class:`~.team.Team` uses them whenever the team
runs the paper's blocks (any thresholds rule included: ⁱμ_k comes in as a
:class:`~.thresholds.paper.ThresholdRecord`, eq. 40 as its factors, another rule as an
array), and composes the blocks' Python methods otherwise (:mod:`.general`).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from ..applied import DriveRecord, lag_input, limit_input
from ..controller import ControllerRecord, collective_one
from ..decision import (
    DecisionRecord,
    bound_squares,
    decide_row,
    entry_share,
    quiet_row,
    quiet_sums,
    unchanged_row,
)
from ..estimate_alarm import AlarmRecord, watch_estimates
from ..fault_estimator import EstimatorRecord, estimate_faults
from ..observer import (
    ObserverRecord,
    advance_one,
    estimate_one,
    integrate_inputs,
    residual_row,
    row_norms,
)
from ..supervisor import SupervisorRecord, Surroundings, supervise
from ..thresholds.paper import ThresholdRecord, refresh_bound
from .records import flat_call

RAISED = 1  # some flag was raised (detection events to report)
SWITCHED = 2  # some robot switched behaviour (reactive events to report)
SATURATED = 4  # some robot's nominal input was beyond its command range (saturated)


class PeriodInputs(NamedTuple):
    """What a period is given: the measurements, the members and the mission."""

    x_m: np.ndarray  # (N, n) each robot's own noisy position
    rows: np.ndarray  # (M,) team row i is robot rows[i]
    c: np.ndarray  # (n,) the desired centroid σ₁,d and its velocity
    c_dot: np.ndarray
    offsets: np.ndarray  # (M, n) the formation's slots and their rates
    rates: np.ndarray
    fdir: bool  # the fault estimator and the decision run
    round_now: bool  # the observers step and the decision runs (every period: ideal network)
    estimates: bool  # write ⁱx̂ into the buffers (a log row or a snapshot reads them)
    norms: bool  # write ‖ⁱr_k‖ into r_norm (a log row, a snapshot or an exclusion reads them)


class PeriodBuffers(NamedTuple):
    """The period's outputs and scratch, allocated by the team at its size."""

    x_own: np.ndarray  # (M, n) the members' own measurements
    x_d: np.ndarray  # (M, n) the mission's desired positions and velocities (eq. 14)
    xd_dot: np.ndarray
    x_hat: np.ndarray  # (M, M, n) the estimates before the update (eq. 21)
    u_g: np.ndarray  # (M, n) u_g,i (eq. 16)
    u_mem: np.ndarray  # (M, n) uᵢ, then Δuᵢ (eqs. 8, 22)
    du: np.ndarray
    row: np.ndarray  # (B, M·n) one robot's residual, for each of B groups of robots (scratch)
    # (M + B, M) ‖ⁱr_k‖ in rows 0 .. M - 1 at the periods that keep them (norms), else in
    # row M + b for the robots of group b (scratch)
    r_norm: np.ndarray
    u: np.ndarray  # (N, 2) nominal input, original robot axis
    u_bar: np.ndarray  # (N, 2) the compensated command (eq. 28)
    grid: np.ndarray  # the supervisor's grid of teammates (supervisor.grid_work(M), scratch)
    scale: np.ndarray  # (M·n,) this period's b_k² for the residual loop's test (bound_squares)


@njit(cache=True, nogil=True, inline="always")
def team_rows(inp, ob, ctl, th, dec, out, lo, hi, b):  # pragma: no cover - compiled
    """The pass over the team's N × N state for robots ``lo`` .. ``hi - 1``, robot by robot
    (row i: robot i's own state, its own measurement and its in-neighbours' messages only),
    with scratch row ``b`` of ``out.row``; returns how many flags were raised. It holds no
    lock on Python (``nogil``): several threads run disjoint ranges of robots at once
    (:class:`~.sharing.Sharing`).

    For robot i: ⁱx̂ (eq. 21, into ``x_hat`` when ``estimates``: only where a log row or a
    snapshot reads it) and ∫ ⁱû_g advanced (eqs. 15, 20); at a round of the observers
    (``round_now``) its residual ⁱr (eq. 35), the norms ‖ⁱr_k‖ into ``r_norm`` when
    ``norms`` (only a log row, a snapshot or an exclusion reads them), ⁱŷ of the next period
    (eq. 19) into ``y_next`` and, with
    FDIR, its flags (eq. 39, :func:`~.decision.decide_row`, with the thresholds ``th`` read
    entry by entry). Where the norms are not kept, a row at rest is first tested from the
    residual itself: in the residual's own loop, each entry against its share of eq. 40's
    bound (:func:`~.decision.quiet_sums`), else from the squares
    (:func:`~.decision.quiet_row`: compared as they are computed, none stored, no square
    root); only a row that may change takes its norms, into a scratch row. Every
    N × N array is read or written once per period. The residual reads only ŷ, ∫u and the
    measurements, which neither this pass nor :func:`act` and :func:`deliver` change, so
    the pass may run beside them and the physics; :func:`integrate` follows it."""
    m, _, n = ob.y_hat.shape
    mn = m * n
    y, s = ob.y_hat.reshape(m, mn), ob.int_u_hat.reshape(m, mn)
    yn, xh = ob.y_next.reshape(m, mn), out.x_hat.reshape(m, mn)
    xd, vd, kc, dt = out.x_d.reshape(-1), out.xd_dot.reshape(-1), ctl.kc, ob.dt
    ko, dt_o = ob.ko, ob.dt_o
    write_xh, round_now = inp.estimates, inp.round_now
    row = out.row[b]  # robot i's residual: this thread's scratch
    count = 0
    # one-dimensional views of each robot's rows, and the round's stages written out here
    # rather than in a helper: loops the compiler vectorises (a helper cost 12 % at N = 400)
    for i in range(lo, hi):
        yi, si = y[i], s[i]
        if write_xh:
            xhi = xh[i]
            for a in range(mn):
                xhi[a] = estimate_one(yi[a], si[a])  # eq. 21
        for a in range(mn):  # ∫ ⁱû_g of eq. 15 (eq. 20), at ⁱx̂ of eq. 21
            si[a] += dt * collective_one(vd[a], kc, xd[a], estimate_one(yi[a], si[a]))
        if not round_now:
            continue
        over = residual_row(  # eq. 35, each entry tested against its share of eq. 40's bound
            ob.y_hat,
            ob.int_u_own,
            out.x_own,
            ob.src,
            ob.first_edge,
            ob.in_degree,
            ob.links,
            ob.networked,
            i,
            row,
            out.scale,
            entry_share(th, i, n) if inp.fdir and not inp.norms else np.nan,
        )
        norms = out.r_norm[i if inp.norms else m + b]
        if inp.norms:
            row_norms(row, n, norms)
        yni = yn[i]  # ⁱŷ of the next period (eq. 19)
        for a in range(mn):
            yni[a] = advance_one(yi[a], row[a], ko, dt_o)
        if not inp.fdir:
            continue
        if inp.norms:
            if unchanged_row(norms, th, i, dec):  # at rest, every norm at most ⁱμ_k
                continue
        elif quiet_sums(over, row, n, th, i, dec):  # at rest, every entry below its share
            continue
        elif quiet_row(row, n, th, i, dec):  # at rest, every square below (ⁱμ_k)²
            continue
        else:  # a row that may change: its norms (the skips only save work)
            row_norms(row, n, norms)
        count += decide_row(norms, th, i, dec)  # eq. 39
    return count


@njit(cache=True, inline="always")
def begin(
    inp: PeriodInputs,
    ob: ObserverRecord,
    ctl: ControllerRecord,
    th: ThresholdRecord,
    out: PeriodBuffers,
) -> None:  # pragma: no cover - compiled
    """Stage 1: the members' own measurements, the mission's x_d = J⁻¹σ_d (eq. 14) and
    each robot's u_g,i = Γᵢ ⁱû_g (eq. 16) from its own block of ⁱx̂ (eq. 21), before ∫ moves;
    with FDIR at a round, this period's scale of the decision's test in the residual's
    loop (:func:`~.decision.bound_squares`)."""
    x_m, rows, c, c_dot, offsets, rates = (
        inp.x_m,
        inp.rows,
        inp.c,
        inp.c_dot,
        inp.offsets,
        inp.rates,
    )
    y, s, kc = ob.y_hat, ob.int_u_hat, ctl.kc
    for i in range(rows.shape[0]):
        for d in range(c.shape[0]):
            out.x_own[i, d] = x_m[rows[i], d]
            out.x_d[i, d] = c[d] + offsets[i, d]
            out.xd_dot[i, d] = c_dot[d] + rates[i, d]
            e = estimate_one(y[i, i, d], s[i, i, d])
            out.u_g[i, d] = collective_one(out.xd_dot[i, d], kc, out.x_d[i, d], e)
    if inp.fdir and inp.round_now and not inp.norms:
        bound_squares(th, y.shape[2], out.scale)


@njit(cache=True, inline="always")
def act(
    inp: PeriodInputs,
    sup: SupervisorRecord,
    seen: Surroundings,
    drive: DriveRecord,
    out: PeriodBuffers,
) -> int:  # pragma: no cover - compiled
    """Stage 2: each robot's nominal input (eqs. 8, 18, 22) within its drive's acceleration
    and range (Remark 4.1); returns SWITCHED | SATURATED bits."""
    code = 0
    if supervise(
        out.x_own,
        out.u_g,
        seen.obstacles,
        seen.safe,
        seen.activation,
        sup.theta,
        sup.release,
        sup.active,
        out.u_mem,
        out.du,
        seen.mates,
        sup.mate_safe,
        sup.mate_act,
        out.grid,
        sup.limit,
    ):
        code |= SWITCHED
    if limit_input(
        out.u_mem, out.u_g, out.du, drive.input_limit, drive.command, inp.rows, drive.accel_step,
        sup.active, drive.full_step,
    ):  # fmt: skip
        code |= SATURATED
    return code


@njit(cache=True, inline="always")
def deliver(
    inp: PeriodInputs,
    drive: DriveRecord,
    est: EstimatorRecord,
    alarm: AlarmRecord,
    out: PeriodBuffers,
) -> None:  # pragma: no cover - compiled
    """Stage 3: the inputs on the robot axis (an excluded robot is told to stay), the drive's
    lag and (with FDIR) every robot's fault estimator and ū (eqs. 28-31) and its own alarm
    (:mod:`.estimate_alarm`): the commands are out, and the physics may advance while the
    pass runs."""
    rows, u, u_mem, du, u_bar, command = (
        inp.rows,
        out.u,
        out.u_mem,
        out.du,
        out.u_bar,
        drive.command,
    )
    m = rows.shape[0]
    if m < u.shape[0]:
        u[:] = 0.0
    for i in range(m):
        for d in range(2):
            u[rows[i], d] = u_mem[i, d]
    if drive.lagged:  # the drives' lag: integrate what they deliver, command the drives
        lag_input(u, drive.v_hat, command, drive.lag_a, drive.lag_b)
        for i in range(m):
            for d in range(2):
                u_mem[i, d] = u[rows[i], d]
                du[i, d] = u_mem[i, d] - out.u_g[i, d]
    else:  # loops, not command[:] = u: a slice copy compiles numba's shape-mismatch message
        for r in range(u.shape[0]):
            for d in range(2):
                command[r, d] = u[r, d]
    if not inp.fdir:
        for r in range(u.shape[0]):
            for d in range(2):
                u_bar[r, d] = command[r, d]
        return
    applied = est.applied
    estimate_faults(
        inp.x_m,
        u,
        est.z,
        est.int_e,
        est.phi_hat,
        applied,
        est.K,
        est.g_inv,
        est.dt,
        est.limit,
        est.alpha,
        est.hold,
        u_bar,
    )
    for r in range(u.shape[0]):
        for d in range(2):
            u_bar[r, d] = command[r, d] - (applied[r, d] if est.compensate else 0.0)  # eq. 28
    if alarm.on:
        a = alarm
        watch_estimates(est.phi_hat, u_bar, a.phi_bar, a.limit, a.need, a.timer, a.alarm, a.seen)


@njit(cache=True, inline="always")
def integrate(ob: ObserverRecord, out: PeriodBuffers) -> None:  # pragma: no cover - compiled
    """Stage 5, after the pass: ∫ Γᵢᵀ Δuᵢ and ∫uᵢ (eqs. 20-21), added after the pass's ∫ ⁱû_g."""
    integrate_inputs(ob.int_u_hat, ob.int_u_own, out.du, out.u_mem, ob.dt)


@njit(cache=True, nogil=True, inline="always")
def commands(
    inp: PeriodInputs,
    sup: SupervisorRecord,
    seen: Surroundings,
    drive: DriveRecord,
    est: EstimatorRecord,
    alarm: AlarmRecord,
    out: PeriodBuffers,
) -> int:  # pragma: no cover - compiled
    """Stages 2-3, after :func:`begin`: :func:`act` and :func:`deliver`, every robot's
    commands; returns SWITCHED | SATURATED bits. They read and write nothing the pass over
    the N × N state (:func:`team_rows`) does, so the two may run at once; like the pass it
    holds no lock on Python (``nogil``), or a helper thread could not begin its rows until
    the commands end (at N = 1000 it began 0.31 ms after it was handed them, 0.04 ms since)."""
    code = act(inp, sup, seen, drive, out)
    deliver(inp, drive, est, alarm, out)
    return code


@njit(inline="always")
def team_period(
    inp: PeriodInputs,
    th: ThresholdRecord,
    ob: ObserverRecord,
    ctl: ControllerRecord,
    sup: SupervisorRecord,
    seen: Surroundings,
    drive: DriveRecord,
    est: EstimatorRecord,
    alarm: AlarmRecord,
    dec: DecisionRecord,
    out: PeriodBuffers,
) -> int:  # pragma: no cover - compiled
    """One period for the members ``inp.rows`` on one core; returns RAISED | SWITCHED |
    SATURATED bits. The stages: :func:`begin`, the commands (:func:`commands`:
    :func:`act`, :func:`deliver`), the pass over the N × N state (eqs. 21, 15, 20, 35, 19
    and the decision of eq. 39, :func:`team_rows`) and :func:`integrate`; a large team runs
    the same stages called one by one, the pass shared between threads (:class:`~.sharing.Sharing`).
    The stages are inlined here (``inline="always"``): as calls they cost 1.7 µs of this
    function's 3.9 at N = 4 (measured inside compiled code), since every call passes the
    records' arrays with their reference counts.

    ``inp.x_m``, the drive's ``v_hat`` and ``command``, the estimator's arrays and
    ``out.u``, ``out.u_bar`` are on the original robot axis (N); with a drive lag
    (``drive.lagged``) ``out.u`` ends as the velocity the drive model predicts and
    ``drive.command`` as what the drive is told; the others on the members' axis (M).
    Robots that are not members get u = 0 and only run their fault estimator. ŷ of the
    next period goes to ``ob.y_next`` (the observer swaps it in, :meth:`.Observer.advance`).
    """
    refresh_bound(th)  # the bound of ‖ỹ*_k(t)‖ in eq. 40, until it settles
    begin(inp, ob, ctl, th, out)
    code = commands(inp, sup, seen, drive, est, alarm, out)
    raised = team_rows(inp, ob, ctl, th, dec, out, 0, inp.rows.shape[0], 0)
    integrate(ob, out)
    return code | RAISED if raised else code


@njit(inline="always")
def shared_begin(inp, th, ob, ctl, sup, seen, drive, est, alarm, dec, out):  # pragma: no cover
    """A shared period's first stage: the bound of eq. 40 (until it settles), then
    :func:`begin`; the pass may start once it has returned."""
    refresh_bound(th)
    begin(inp, ob, ctl, th, out)


@njit(inline="always")
def shared_commands(inp, th, ob, ctl, sup, seen, drive, est, alarm, dec, out):  # pragma: no cover
    """A shared period's :func:`commands`, beside the pass."""
    return commands(inp, sup, seen, drive, est, alarm, out)


@njit(inline="always")
def shared_rows(
    inp, th, ob, ctl, sup, seen, drive, est, alarm, dec, out, lo, hi, b
):  # pragma: no cover - compiled
    """Robots ``lo`` .. ``hi - 1`` of a shared period's pass (:func:`team_rows`), with the
    scratch row ``b`` of the thread that runs them."""
    return team_rows(inp, ob, ctl, th, dec, out, lo, hi, b)


@njit(inline="always")
def shared_integrate(inp, th, ob, ctl, sup, seen, drive, est, alarm, dec, out):  # pragma: no cover
    """A shared period's last stage, :func:`integrate`, once the pass has ended."""
    integrate(ob, out)


#: the records every entry takes, in order (their fields, :func:`~.records.fields`)
RECORDS = (
    PeriodInputs,
    ThresholdRecord,  # the two records a period may change come first
    ObserverRecord,
    ControllerRecord,
    SupervisorRecord,
    Surroundings,
    DriveRecord,
    EstimatorRecord,
    AlarmRecord,
    DecisionRecord,
    PeriodBuffers,
)
#: :func:`team_period` as one compiled call
team_period_call = flat_call(team_period, RECORDS, "team_period_call", __name__)
#: the stages of a shared period, one call each (the commands and the rows hold no lock on
#: Python: they run at once in different threads)
begin_call = flat_call(shared_begin, RECORDS, "begin_call", __name__)
commands_call = flat_call(shared_commands, RECORDS, "commands_call", __name__, nogil=True)
rows_call = flat_call(
    shared_rows, RECORDS, "rows_call", __name__, extra=("lo", "hi", "b"), nogil=True
)
integrate_call = flat_call(shared_integrate, RECORDS, "integrate_call", __name__)
