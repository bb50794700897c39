"""One control period of the whole team with the paper's blocks, compiled.

This is not a second implementation: it calls, in the order of Fig. 1, the
same compiled functions the blocks call (observer :func:`~.observer.estimate_one`,
:func:`~.observer.residual_row`, :func:`~.observer.advance_one`,
:func:`~.observer.integrate_inputs`; controller :func:`~.controller.collective_one`;
supervisor :func:`~.supervisor.supervise`; fault estimator
:func:`~.fault_estimator.estimate_faults`; decision :func:`~.decision.decide_row`;
thresholds :func:`~.thresholds.paper.threshold_at`), each equation written once (only the
mission's x_d = c + offsets of eq. 14, one addition, is spelled out in both paths). It reads
and writes the blocks' state records (each block's ``record()``) and reaches into no block.
The stages, in the order of Fig. 1: :func:`begin`; one pass over the team's N × N state,
robot by robot (:func:`_rows`: u_g,i, ⁱx̂, ∫ⁱû_g, then at a round the residual, its norms,
the next ŷ, written to a second buffer the observer swaps in since every robot reads its
in-neighbours' current messages, and the flags); :func:`act`; :func:`deliver`. On a network
the residual and the decision run only at the observers' rounds (``PeriodInputs.round_now``),
on the messages the links delivered (``ObserverRecord.links``); every period on the ideal
network. :func:`team_period` runs them as one compiled call on one core (the team calls it
through :func:`team_period_flat`); :func:`team_period_split` runs the pass over every core,
for teams of :data:`PARALLEL_FROM` robots or more. :class:`~.team.Team` uses them whenever
the team runs the paper's blocks (any thresholds rule included: ⁱμ_k comes in as a
:class:`~.thresholds.paper.ThresholdRecord`, eq. 40 as its factors, another rule as an
array), and composes the blocks' Python methods otherwise (:mod:`.general`).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit, prange

from .applied import DriveRecord, lag_input, limit_input
from .controller import ControllerRecord, collective_one
from .decision import DecisionRecord, decide_row
from .fault_estimator import EstimatorRecord, estimate_faults
from .observer import (
    ObserverRecord,
    advance_one,
    estimate_one,
    integrate_inputs,
    residual_row,
    row_norms,
)
from .parallel import twin
from .supervisor import SupervisorRecord, Surroundings, supervise
from .thresholds.paper import ThresholdRecord

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
    r_norm: np.ndarray  # (M, M) ‖ⁱr_k‖
    u: np.ndarray  # (N, 2) nominal input, original robot axis
    u_bar: np.ndarray  # (N, 2) the compensated command (eq. 28)


@njit(inline="always")
def _round_row(inp, ob, th, dec, out, i, row, y, yn, n):  # pragma: no cover - compiled
    """Robot i at a round of the observers: ⁱr (eq. 35), ‖ⁱr_k‖, ⁱŷ of the next period
    (eq. 19) and, with FDIR, its flags (eq. 39); returns how many it raised."""
    residual_row(
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
    )
    row_norms(row, i, n, out.r_norm)
    for a in range(y.shape[1]):
        yn[i, a] = advance_one(y[i, a], row[a], ob.ko, ob.dt_o)
    if not inp.fdir:
        return 0
    return decide_row(out.r_norm, th, i, dec)


def _rows(inp, ob, ctl, th, dec, out):  # pragma: no cover - compiled
    """The one pass over the team's N × N state, robot by robot (row i: robot i's own state,
    its own measurement and its in-neighbours' messages only), in as many contiguous groups
    of robots as ``rows`` (B, M·n) has scratch rows; returns how many flags were raised.

    For robot i: u_g,i (eq. 16, its own block, before ∫ moves), ⁱx̂ (eq. 21, into ``xh``
    when ``write_xh``: only where a log row or a snapshot reads it) and ∫ ⁱû_g advanced in
    ``s`` (eqs. 15, 20); at a round of the observers (``round_now``) its residual ⁱr
    (eq. 35), the norms ‖ⁱr_k‖ into ``r_norm``, ⁱŷ of the next period (eq. 19) into ``yn``
    and, with FDIR, its flags (eq. 39, :func:`~.decision.decide_row`, with the
    thresholds ``th`` read entry by entry). Every N × N array is read or written once per
    period; the residual reads only ŷ and ∫u, which this pass does not change, so its
    order against the integrals is free."""
    m, _, n = ob.y_hat.shape
    y, s = ob.y_hat.reshape(m, m * n), ob.int_u_hat.reshape(m, m * n)
    yn, xh = ob.y_next.reshape(m, m * n), out.x_hat.reshape(m, m * n)
    xd, vd, u_g, kc, dt = out.x_d.reshape(-1), out.xd_dot.reshape(-1), out.u_g, ctl.kc, ob.dt
    rows, write_xh, round_now = out.row, inp.estimates, inp.round_now
    blocks = rows.shape[0]
    count = 0
    for b in prange(blocks):
        row = rows[b]
        for i in range(b * m // blocks, (b + 1) * m // blocks):
            for d in range(n):  # u_g,i = Γᵢ ⁱû_g (eq. 16): robot i's own block, before ∫ moves
                a = i * n + d
                u_g[i, d] = collective_one(vd[a], kc, xd[a], estimate_one(y[i, a], s[i, a]))
            for a in range(m * n):
                e = estimate_one(y[i, a], s[i, a])  # eq. 21
                if write_xh:
                    xh[i, a] = e
                s[i, a] += dt * collective_one(vd[a], kc, xd[a], e)  # ∫ ⁱû_g of eq. 15 (eq. 20)
            if round_now:
                count += _round_row(inp, ob, th, dec, out, i, row, y, yn, n)
    return count


# the pass over the team's N × N state on one core, or split over the cores (a team of
# PARALLEL_FROM robots or more: below it, starting the threads costs more than it saves)
team_rows = njit(cache=True)(_rows)
team_rows_parallel = njit(cache=True, parallel=True)(twin(_rows, "_rows_parallel"))
PARALLEL_FROM = 200


@njit(cache=True)
def begin(inp: PeriodInputs, out: PeriodBuffers) -> None:  # pragma: no cover - compiled
    """Stage 1: the members' own measurements, and the mission's x_d = J⁻¹σ_d (eq. 14)."""
    x_m, rows, c, c_dot, offsets, rates = (
        inp.x_m,
        inp.rows,
        inp.c,
        inp.c_dot,
        inp.offsets,
        inp.rates,
    )
    for i in range(rows.shape[0]):
        for d in range(c.shape[0]):
            out.x_own[i, d] = x_m[rows[i], d]
            out.x_d[i, d] = c[d] + offsets[i, d]
            out.xd_dot[i, d] = c_dot[d] + rates[i, d]


@njit(cache=True)
def act(
    inp: PeriodInputs,
    sup: SupervisorRecord,
    seen: Surroundings,
    drive: DriveRecord,
    out: PeriodBuffers,
) -> int:  # pragma: no cover - compiled
    """Stage 3: each robot's nominal input (eqs. 8, 18, 22) within its drive's acceleration
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
    ):
        code |= SWITCHED
    if limit_input(
        out.u_mem, out.u_g, out.du, drive.input_limit, drive.command, inp.rows, drive.accel_step
    ):
        code |= SATURATED
    return code


@njit(cache=True)
def deliver(
    inp: PeriodInputs,
    ob: ObserverRecord,
    drive: DriveRecord,
    est: EstimatorRecord,
    out: PeriodBuffers,
) -> None:  # pragma: no cover - compiled
    """Stage 5: the inputs on the robot axis (an excluded robot is told to stay), the drive's
    lag, ∫u (eqs. 20-21), and (with FDIR) every robot's fault estimator and ū (eqs. 28-31)."""
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
    if drive.lag_a > 0.0:  # the drive's lag: integrate what it delivers, command the drive
        lag_input(u, drive.v_hat, command, drive.lag_a, drive.lag_b)
        for i in range(m):
            for d in range(2):
                u_mem[i, d] = u[rows[i], d]
                du[i, d] = u_mem[i, d] - out.u_g[i, d]
    else:
        command[:] = u
    integrate_inputs(ob.int_u_hat, ob.int_u_own, du, u_mem, ob.dt)  # eqs. 20-21
    if not inp.fdir:
        u_bar[:] = command
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


@njit(cache=True)
def team_period(
    inp: PeriodInputs,
    ob: ObserverRecord,
    ctl: ControllerRecord,
    sup: SupervisorRecord,
    seen: Surroundings,
    drive: DriveRecord,
    est: EstimatorRecord,
    th: ThresholdRecord,
    dec: DecisionRecord,
    out: PeriodBuffers,
) -> int:  # pragma: no cover - compiled
    """One period for the members ``inp.rows`` on one core; returns RAISED | SWITCHED |
    SATURATED bits. The stages in the order of Fig. 1: :func:`begin`, the pass over the
    N × N state (eqs. 16, 21, 15, 20, 35, 19 and the decision of eq. 39, :func:`_rows`),
    :func:`act`, :func:`deliver`; :func:`team_period_split` runs the same stages with the
    pass over every core.

    ``inp.x_m``, the drive's ``v_hat`` and ``command``, the estimator's arrays and
    ``out.u``, ``out.u_bar`` are on the original robot axis (N); with a drive lag
    (``drive.lag_a`` > 0) ``out.u`` ends as the velocity the drive model predicts and
    ``drive.command`` as what the drive is told; the others on the members' axis (M).
    Robots that are not members get u = 0 and only run their fault estimator. ŷ of the
    next period goes to ``ob.y_next`` (the observer swaps it in, :meth:`.Observer.advance`).
    """
    begin(inp, out)
    raised = team_rows(inp, ob, ctl, th, dec, out)
    code = act(inp, sup, seen, drive, out)
    deliver(inp, ob, drive, est, out)
    return code | RAISED if raised else code


def team_period_split(
    inp: PeriodInputs,
    ob: ObserverRecord,
    ctl: ControllerRecord,
    sup: SupervisorRecord,
    seen: Surroundings,
    drive: DriveRecord,
    est: EstimatorRecord,
    th: ThresholdRecord,
    dec: DecisionRecord,
    out: PeriodBuffers,
) -> int:
    """:func:`team_period`'s stages with the pass over the N × N state run in
    ``out.row.shape[0]`` groups of robots over every core: the same arithmetic per robot,
    so the same numbers bit for bit. Called stage by stage from Python (a few µs, nothing
    at the N ≥ PARALLEL_FROM it is for): a compiled caller of the parallel pass pays the
    thread pool's cost even where it runs it on one core (4.5 µs per period at N = 4)."""
    begin(inp, out)
    raised = team_rows_parallel(inp, ob, ctl, th, dec, out)
    code = act(inp, sup, seen, drive, out)
    deliver(inp, ob, drive, est, out)
    return int(code | RAISED if raised else code)


@njit(cache=True)
def team_period_flat(*a):  # pragma: no cover - compiled
    """:func:`team_period` with the records' fields passed one by one, in the records' order
    (``team_period_flat(*inputs, *observer, ..., *buffers)``), the records rebuilt inside
    compiled code, where building them costs nothing. At the boundary numba types a tuple
    argument element by element in Python on every call (10 µs for the records at N = 4,
    twice the period's arithmetic) and a flat argument list in its C fast path. The slices
    below are checked against the records' field counts (:data:`RECORDS`)."""
    return team_period(
        PeriodInputs(*a[0:9]),
        ObserverRecord(*a[9:21]),
        ControllerRecord(*a[21:22]),
        SupervisorRecord(*a[22:27]),
        Surroundings(*a[27:31]),
        DriveRecord(*a[31:37]),
        EstimatorRecord(*a[37:48]),
        ThresholdRecord(*a[48:53]),
        DecisionRecord(*a[53:60]),
        PeriodBuffers(*a[60:71]),
    )


#: the records :func:`team_period` takes, in order (``team_period_flat`` slices them)
RECORDS = (
    PeriodInputs,
    ObserverRecord,
    ControllerRecord,
    SupervisorRecord,
    Surroundings,
    DriveRecord,
    EstimatorRecord,
    ThresholdRecord,
    DecisionRecord,
    PeriodBuffers,
)
_ENDS = (9, 21, 22, 27, 31, 37, 48, 53, 60, 71)  # where each record ends in team_period_flat's a
if tuple(np.cumsum([len(r._fields) for r in RECORDS])) != _ENDS:  # pragma: no cover
    raise ImportError("team_period_flat's slices no longer match the records' fields")
